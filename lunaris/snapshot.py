"""``lunaris snapshot save|restore|list ROVER [NAME]`` (see :mod:`lunaris.session_cli`)."""

from lunaris.session_cli import add_snapshot_arguments as add_arguments
from lunaris.session_cli import main_snapshot as main

__all__ = ["add_arguments", "main"]
