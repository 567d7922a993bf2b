"""The live front end (rclpy): the node (``node``), what it reports (``diagnostics``), its parameters
(``parameters``), its numeric status topics for plotting tools (``status``), the message classes it
publishes with (``messages``), and ``evsync play``.

``parameters`` reads and checks parameter files without rclpy, so the CLI and the tests use it too.
"""
