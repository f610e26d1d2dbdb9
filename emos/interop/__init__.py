"""Working with the tools robots already use: ROS 2 CDR encodings, MCAP recordings, Foxglove.

Heavy third-party libraries (rosbags, mcap, foxglove-sdk) are imported only by the modules
that need them; they come with the ``ecosystem`` extra.
"""
