"""The twin's reasons in words a person uses (``heat_w must be at least 0 (got -3)``, not
``Expected `float` >= 0.0 - at `$.heat_w```): the one copy is :mod:`common.reasons`, which
the services' own rejections use too; the tools take it from here."""

from __future__ import annotations

from common.messages import humane
from common.reasons import shown

__all__ = ["humane", "shown"]
