"""Adapters between serialized event messages (CDR bytes) and numpy arrays.

One module per message type and encoding: ``event_packet`` (EventPacket fields, the per-encoding
dispatch and restamping) over ``evt3``, ``libcaer_cmp``, ``libcaer``, ``mono`` and ``trigger``;
``event_array`` for dvs_msgs and prophesee_event_msgs EventArray. ``registry`` picks the adapter
for a type name; ``definitions`` holds the message definitions registered with rosbags; ``edges``
the trigger edges the decoders also give. The stateful word loops are C (``_kernels.c``, built by
setup.py).
"""
