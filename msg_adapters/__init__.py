"""Adapters between serialized event messages (CDR bytes) and numpy arrays.

One module per message type and encoding. ``definitions`` holds the message definitions the
adapters and the bag tools register with rosbags.
"""
