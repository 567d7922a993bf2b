"""Process plumbing of the live node: runners in processes of their own, the worker, the wire
form camera processes send. Not numpy-only core: the engine takes a ``core.runner.Runner``."""
