"""The ``evsync`` command: commands, tables, plots and progress."""
