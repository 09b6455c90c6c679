"""``lunaris reset ROVER``: the rover back to its rover file (see :mod:`lunaris.session_cli`)."""

from lunaris.session_cli import add_reset_arguments as add_arguments
from lunaris.session_cli import main_reset as main

__all__ = ["add_arguments", "main"]
