"""``lunaris session start ROVER --trainee NAME [--from-snapshot S]`` and ``lunaris session list
ROVER`` (see :mod:`lunaris.session_cli`)."""

from lunaris.session_cli import add_session_arguments as add_arguments
from lunaris.session_cli import main_session as main

__all__ = ["add_arguments", "main"]
