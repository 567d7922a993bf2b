"""The live front end (rclpy): the node, its parameters, and `evsync play`.

``parameters`` reads and checks parameter files without rclpy; ``node`` and ``play`` need it.
"""
