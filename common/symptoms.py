"""What the crew can see of each fault kind (SPEC §12b, §12d): the value it moves, and the band
that value kept before the fault, outside which the move is a symptom.

Pure data and arithmetic, read by :mod:`common.response` (which also counts the twin's own
alarms as symptoms) and by the reference (``docs/reference/scenarios.md``). A value's band is
its range over the ``WINDOW_S`` before the fault, kept as ``BUCKET_S`` slices (bounded whatever
the rate), widened by its :data:`TOLERANCE` and, for smooth values, by the trend it had: a
temperature already rising must rise faster than it did to be a symptom.

A load's power is what it draws on a live rail: its samples while its rail is off (0 W, for
every load whatever ails it) are neither part of its band nor a symptom. An open load shows as
nothing drawn on a live rail: its power falling below its band, or, its rail off all the minute
before the fault (no band), 0 W once its rail is on - the camera the crew switches on after the
fault, and sees at 0 W (found by an instructor: that open circuit had no symptom). The
umbilical's supply counts the same way only while it is plugged in (its state says connected,
or the last ``input/umbilical`` heard plugged it in: a cut umbilical says it is not connected,
plugged or not), and a cut one shows as nothing supplied once plugged in.

Every kind of the catalogue has a symptom here. A fault's symptom stays ``null`` when it moves
nothing the crew's topics show:

- a parameter that changes nothing (SPEC §12e: heating 0 W, dust 0, capacity loss 0,
  resistance x1): every value stays where it was;
- a load's fault on a rail that stays off (short, open, stuck): an off rail feeds nothing, so a
  load on it draws 0 W whatever ails it; the symptom comes when the rail comes on (a short's
  trip, an open's 0 W); a load stuck at what it drew anyway;
- a pack's resistance with no current through it: nothing to sag;
- a panel's dust or disconnection while the panel is dark and stays so: it gave nothing and
  gives nothing;
- the umbilical's supply cut while it is unplugged and stays so (an unplugged umbilical
  supplies nothing anyway);
- a radio's failure or reduced range while the rover stays out of its range, or (reduced
  range) stays in it: the link says what it said.

It also stays ``null`` where the crew could tell, but only against what it knows of the rover
and no band before the fault holds it (limits, not claims that nothing shows):

- a stuck load whose rail was off the whole minute before the fault, once the rail is on: its
  stuck power against the rover file's ``nominal_w``, which no recording holds;
- dust on a panel dark at the fault, once the sun is on it: less power than the sun's angle
  gives;
- a radio failed or degraded while the rover was out of range, once it is back where it should
  be in range: the link stays lost.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

__all__ = ["BUCKET_S", "RECENT", "SMOOTH_POWER", "SYMPTOMS", "TOLERANCE", "TREND_MIN_S", "UNSEEN_ALARMS",
           "WINDOW_S", "Band", "Direction", "Series", "SymptomSpec", "quantity"]

WINDOW_S = 60.0  # the band a value kept before a fault: over this much sim time
BUCKET_S = 1.0  # ... kept as the range of each such slice (bounded, whatever the rate)
RECENT = 64  # the latest raw samples of a value, for an injection heard after its effect
TREND_MIN_S = 5.0  # a trend is read from at least this much history
Direction = Literal["up", "down", "any", "change", "lost", "nothing"]


class SymptomSpec(NamedTuple):
    """What the crew sees of one fault kind: the value (``{name}``: the faulty component's
    name) and how it moves, in words for the reference."""

    family: str  # key chunks after lunaris/<rover>/, {name} for the component's name
    field: str
    # up, down, any: leaves its band so; change: differs; lost: true -> false; nothing: falls
    # below its band, or, with no band (never live before the fault), is nothing (0) when live
    direction: Direction
    words: str
    live: str = ""  # nothing: when the value counts, in words ("on a live rail")


# fault (component, kind) -> its symptom on a value. Every kind also has the alarm symptom.
SYMPTOMS: dict[tuple[str, str], SymptomSpec] = {
    ("battery", "capacity_loss"): SymptomSpec(
        "battery/state", "capacity_j", "down", "the pack's capacity (and charge) drops"),
    ("battery", "resistance"): SymptomSpec(
        "battery/state", "voltage_v", "down", "the pack's voltage sags below what it did before"),
    ("battery", "heating"): SymptomSpec(
        "battery/state", "temperature_c", "up",
        "the pack's temperature rises beyond what it did before; over max_c, the "
        "over-temperature alarm"),
    ("battery", "disconnect"): SymptomSpec(
        "battery/state", "operational", "change", "the pack goes off line (no output alarm)"),
    ("load", "short"): SymptomSpec(
        "load/{name}/power", "power_w", "any",
        "its rail trips on over-current (or the load's power leaves its band)"),
    ("load", "open"): SymptomSpec(
        "load/{name}/power", "power_w", "nothing",
        "the load draws nothing (0 W) on a live rail: its power falls, or, its rail off at the "
        "fault, it draws 0 W once the rail is on (none while the rail stays off)",
        "on a live rail"),
    ("load", "stuck"): SymptomSpec(
        "load/{name}/power", "power_w", "any", "the load's power changes (none if it is stuck at "
        "what it drew anyway)"),
    ("rail", "fail"): SymptomSpec(
        "rail/{name}/state", "state", "change", "the rail goes dead (state failed, 0 V)"),
    ("solar", "dust"): SymptomSpec(
        "solar/{name}/power", "power_w", "down",
        "the panel's power falls (the generation and the solar rail's power)"),
    ("solar", "disconnect"): SymptomSpec(
        "solar/{name}/power", "power_w", "down", "the panel's power falls to nothing"),
    ("umbilical", "disconnect"): SymptomSpec(
        "umbilical/state", "power_w", "nothing",
        "the umbilical's supply falls, or, unplugged at the fault, it supplies nothing once "
        "plugged in (none while it stays unplugged)", "plugged in"),
    ("radio", "failure"): SymptomSpec(
        "radio/{name}/link", "in_range", "lost", "the link goes out of range (none while the "
        "rover was out of range anyway)"),
    ("radio", "degraded"): SymptomSpec(
        "radio/{name}/link", "in_range", "lost", "the link goes out of range; none while it "
        "stays in range"),
}

# The twin's alarms (common.faults.DERIVED) that no instrument of the rover measures, so on no
# crew topic and no symptom: (component type, alarm). A load's over-current: the PDM measures
# and trips its channels, the rails (a channel's trip is its rail's alarm, ERROR on the crew's
# /diagnostics); the loads sharing a channel are not told apart. (Found by an instructor: the
# crew's /diagnostics named the shorted camera for the 13 ms before its rail tripped.)
UNSEEN_ALARMS: frozenset[tuple[str, str]] = frozenset({("load", "over_current")})

# field -> (absolute, relative to the value, trend followed): how far outside its band a value
# must go to be a symptom. Loads' power is noisy sample to sample: its band is its range, no
# trend; the others are smooth.
TOLERANCE: dict[str, tuple[float, float, bool]] = {
    "capacity_j": (1.0, 1e-3, False),
    "voltage_v": (0.02, 0.0, True),
    "temperature_c": (0.2, 0.0, True),
    "power_w": (0.05, 0.02, False),
}
SMOOTH_POWER = ("solar", "umbilical")  # power_w of these follows its trend

# -- values and their bands ------------------------------------------------------------------


class Series:
    """One value's recent history: the range of each ``BUCKET_S`` slice over ``WINDOW_S``, and
    its latest raw samples."""

    __slots__ = ("buckets", "recent")

    def __init__(self) -> None:
        self.buckets: deque[list[float]] = deque()  # [start_t, lo, hi, sum, n]
        self.recent: deque[tuple[float, Any]] = deque(maxlen=RECENT)

    def add(self, t: float, v: float) -> None:
        """A number at ``t``."""
        recent = self.recent
        if recent and t < recent[-1][0]:  # time went back (a reset, a straggler): start again
            self.clear()
        recent.append((t, v))
        b = self.buckets
        if b:
            last = b[-1]
            if t < last[0] + BUCKET_S:
                if v < last[1]:
                    last[1] = v
                elif v > last[2]:
                    last[2] = v
                last[3] += v
                last[4] += 1
                return
        b.append([t, v, v, v, 1])
        while b[0][0] < t - WINDOW_S - BUCKET_S:
            b.popleft()

    def add_state(self, t: float, v: Any) -> None:
        """A state (on, in range ...) at ``t``: kept when it changes."""
        recent = self.recent
        if recent:
            last_t, last_v = recent[-1]
            if t < last_t:
                self.clear()
            elif v == last_v:
                return
        recent.append((t, v))

    def clear(self) -> None:
        self.buckets.clear()
        self.recent.clear()

    def before(self, t: float) -> list[tuple[float, float, float, float]]:
        """``(t, lo, hi, mean)`` of the slices wholly before ``t``, and of the raw samples
        before ``t`` in the slice that holds it."""
        out = [(b[0], b[1], b[2], b[3] / b[4]) for b in self.buckets if b[0] + BUCKET_S <= t]
        cut = self.buckets[-1][0] if self.buckets and self.buckets[-1][0] + BUCKET_S > t else t
        out += [(ts, v, v, v) for ts, v in self.recent
                if cut <= ts < t and not isinstance(v, bool) and v is not None]
        return [o for o in out if o[0] >= t - WINDOW_S]

    def last_before(self, t: float) -> Any:
        for ts, v in reversed(self.recent):
            if ts < t:
                return v
        return None


@dataclass
class Band:
    """The band a value kept before a fault, and how far outside it is a symptom."""

    lo: float
    hi: float
    t_ref: float
    v_ref: float
    slope: float
    tol: float

    @classmethod
    def of(cls, points: list[tuple[float, float, float, float]], fld: str, trend: bool) -> Band:
        absolute, relative, _ = TOLERANCE.get(fld, (0.0, 0.0, False))
        lo, hi = min(p[1] for p in points), max(p[2] for p in points)
        first, last = points[0], points[-1]
        slope = 0.0
        if trend and last[0] - first[0] >= TREND_MIN_S:
            slope = (last[3] - first[3]) / (last[0] - first[0])
        tol = max(absolute, relative * max(abs(lo), abs(hi)))
        return cls(lo, hi, last[0], last[3], slope, tol)

    def outside(self, t: float, v: float, direction: Direction) -> str | None:
        """``above`` or ``below`` when ``v`` at ``t`` is outside the band that way, else None."""
        dt = max(0.0, t - self.t_ref)
        upper = max(self.hi, self.v_ref + max(self.slope, 0.0) * dt) + self.tol
        lower = min(self.lo, self.v_ref + min(self.slope, 0.0) * dt) - self.tol
        if direction in ("up", "any") and v > upper:
            return "above"
        if direction in ("down", "any") and v < lower:
            return "below"
        return None

    def words(self, unit: str = "") -> str:
        """``2.7 to 4.78 W``; one value when the band is one."""
        unit = f" {unit}" if unit else ""
        if f"{self.lo:.3g}" == f"{self.hi:.3g}":
            return f"{self.lo:.3g}{unit}"
        return f"{self.lo:.3g} to {self.hi:.3g}{unit}"


_UNITS = (("_w", "W"), ("_v", "V"), ("_c", "°C"), ("_j", "J"), ("_a", "A"))


def quantity(field: str) -> tuple[str, str]:
    """A payload field as words and its unit: ``power_w`` -> ("power", "W")."""
    for suffix, unit in _UNITS:
        if field.endswith(suffix):
            return field[: -len(suffix)].replace("_", " "), unit
    return field.replace("_", " "), ""
