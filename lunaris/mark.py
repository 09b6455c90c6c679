"""``lunaris mark ROVER TEXT``: a mark on the session's timeline (see :mod:`lunaris.session_cli`)."""

from lunaris.session_cli import add_mark_arguments as add_arguments
from lunaris.session_cli import main_mark as main

__all__ = ["add_arguments", "main"]
