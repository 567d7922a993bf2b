"""Recorded bags (rosbags): reading, writing, estimating offsets from a bag, restamped copies."""
