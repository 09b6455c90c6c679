"""Who may use the console, and what they may do.

Without an accounts file the console serves loopback only and the local user is the
instructor: whoever can open the page on this computer can already run ``lunaris`` here.
With an accounts file every page and API call needs a signed-in user, and the console may
listen on other addresses. A user is an ``instructor`` (may change the twin) or an
``observer`` (sees everything, changes nothing: every change it attempts is refused by the
server with HTTP 403, whatever the page shows).

The accounts file is JSON, made and changed with ``lunaris console users add|remove|list``::

    {"users": {"ana": {"role": "instructor", "password_hash": "$argon2id$v=19$..."}}}

Passwords are kept only as Argon2id hashes (``argon2-cffi``); a weak one (shorter than
``MIN_PASSWORD``, a common one, the user's name, one character repeated, a run of the keyboard
or of digits) is refused when the user is added. The file is read again when it changes, so a
user added, removed or given another role counts at once, without a restart; a removed user's
sign-ins end with it, their live streams too. Sign-ins are random tokens held by the server
(an HTTP-only, same-site cookie), for ``SESSION_S`` at most.

Failed sign-ins are counted per user name and per address (:class:`Attempts`): past
``Attempts.FREE`` failures in a row, each further try must wait a lockout that doubles, from
``Attempts.FIRST_S`` up to ``Attempts.MOST_S``; the page says how long.
"""

from __future__ import annotations

import ipaddress
import json
import os
import secrets
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError

__all__ = ["COOKIE", "LOCAL", "ROLES", "Accounts", "AccountsError", "Attempts", "SignIns", "User",
           "is_loopback", "weak_password"]

ROLES = ("instructor", "observer")
Role = Literal["instructor", "observer"]
COOKIE = "lunaris_console"
SESSION_S = 12 * 3600.0
MIN_PASSWORD = 10
# The most used passwords of the published breach lists (the ones of 10 characters or more;
# shorter ones are refused for their length) and a training room's obvious guesses.
COMMON_PASSWORDS = frozenset("""
password123 password12 password1234 passw0rd123 1234567890 0123456789 12345678910 1q2w3e4r5t
qwertyuiop 1qaz2wsx3edc qwerty1234 qwerty12345 abcdefghij abc1234567 iloveyou12 football12
baseball12 superman12 letmein123 welcome123 welcome1234 monkey1234 dragon1234 sunshine12
princess12 trustno123 changeme12 changeme123 administrator admin12345 admin123456 lunaris123
lunaris2024 lunaris2025 instructor instructor1 observer12 mapp123456 rover12345 moonrover1
""".split())
_KEYBOARD_RUNS = ("1234567890", "0987654321", "qwertyuiop", "asdfghjkl", "zxcvbnm",
                  "abcdefghijklmnopqrstuvwxyz", "azertyuiop")
_hasher = PasswordHasher()
_DUMMY = _hasher.hash("not a password of anyone")  # verified against for unknown users


class AccountsError(ValueError):
    """An accounts file that cannot be used, or a change that cannot be made."""


@dataclass(frozen=True)
class User:
    name: str
    role: Role
    local: bool = False  # the loopback user of a console without accounts

    @property
    def may_act(self) -> bool:
        return self.role == "instructor"


LOCAL = User("local user", "instructor", local=True)


def weak_password(name: str, password: str) -> str | None:
    """Why ``password`` is too weak for user ``name``, in words; None when it is not."""
    low = password.lower()
    if len(password) < MIN_PASSWORD:
        return f"the password must have at least {MIN_PASSWORD} characters"
    if low in COMMON_PASSWORDS:
        return "this password is one of the most used ones: choose another"
    if name and name.lower() in low:
        return "the password must not contain the user's name"
    if len(set(password)) <= 2:
        return "the password must not be one or two characters repeated"
    if any(low in run or low in run * 2 for run in _KEYBOARD_RUNS):
        return "the password must not be a run of the keyboard or of digits"
    return None


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Accounts:
    """The accounts file, read again whenever it changes on disk."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._stamp: tuple[int, int] | None = None
        self._users: dict[str, dict] = {}
        self.reload()

    def reload(self) -> None:
        try:
            st = self.path.stat()
        except FileNotFoundError:
            raise AccountsError(f"{self.path}: no such accounts file (make one with "
                                f"lunaris console users add NAME --accounts {self.path})") from None
        stamp = (st.st_mtime_ns, st.st_size)
        if stamp == self._stamp:
            return
        self._users = _read(self.path)
        self._stamp = stamp

    def users(self) -> dict[str, Role]:
        self.reload()
        return {name: u["role"] for name, u in sorted(self._users.items())}

    def user(self, name: str) -> User | None:
        """The user as the file says now (None: no longer there)."""
        self.reload()
        u = self._users.get(name)
        return None if u is None else User(name, u["role"])

    def check(self, name: str, password: str) -> User | None:
        """The user if the password is theirs; the same work is done for an unknown name."""
        self.reload()
        u = self._users.get(name)
        try:
            _hasher.verify(u["password_hash"] if u else _DUMMY, password)
        except (VerificationError, InvalidHashError):
            return None
        return None if u is None else User(name, u["role"])

    # -- changes (the users command) -----------------------------------------------------------

    @staticmethod
    def add(path: str | os.PathLike, name: str, role: str, password: str, replace: bool = False) -> None:
        path = Path(path)
        if role not in ROLES:
            raise AccountsError(f"role must be {' or '.join(ROLES)}, got {role!r}")
        if not name or len(name) > 64 or not all(c.isalnum() or c in "._-@" for c in name):
            raise AccountsError(f"bad user name {name!r}: letters, digits, '.', '_', '-', '@'")
        weak = weak_password(name, password)
        if weak is not None:
            raise AccountsError(weak)
        users = _read(path) if path.exists() else {}
        if name in users and not replace:
            raise AccountsError(f"user {name!r} exists (give --replace to change the role or password)")
        users[name] = {"role": role, "password_hash": _hasher.hash(password)}
        _write(path, users)

    @staticmethod
    def remove(path: str | os.PathLike, name: str) -> None:
        users = _read(Path(path))
        if name not in users:
            raise AccountsError(f"no user {name!r} in {path}")
        del users[name]
        _write(Path(path), users)


def _read(path: Path) -> dict[str, dict]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise AccountsError(f"{path}: not a readable accounts file: {exc}") from None
    users = data.get("users") if isinstance(data, dict) else None
    if not isinstance(users, dict):
        raise AccountsError(f'{path}: expected {{"users": {{NAME: {{"role": ..., "password_hash": ...}}}}}}')
    for name, u in users.items():
        if (not isinstance(u, dict) or u.get("role") not in ROLES
                or not isinstance(u.get("password_hash"), str)):
            raise AccountsError(f"{path}: user {name!r} needs a role ({' or '.join(ROLES)}) and a "
                                "password_hash")
    return users


def _write(path: Path, users: dict[str, dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        json.dump({"users": users}, f, indent=2)
        f.write("\n")
    os.replace(tmp, path)


class SignIns:
    """Random tokens of the signed-in users, held by the server."""

    def __init__(self, accounts: Accounts):
        self.accounts = accounts
        self._tokens: dict[str, tuple[str, float]] = {}  # token -> (user name, expiry)

    def open(self, user: User) -> str:
        now = time.time()
        for old in [t for t, (_, expiry) in self._tokens.items() if expiry <= now]:
            del self._tokens[old]  # the expired go, so the table holds live sign-ins only
        token = secrets.token_urlsafe(32)
        self._tokens[token] = (user.name, now + SESSION_S)
        return token

    def close(self, token: str | None) -> None:
        if token:
            self._tokens.pop(token, None)

    def user(self, token: str | None) -> User | None:
        """The user of a token, as the accounts file says now; None if it is not valid."""
        got = self._tokens.get(token or "")
        if got is None:
            return None
        name, expiry = got
        user = self.accounts.user(name) if time.time() < expiry else None
        if user is None:
            self._tokens.pop(token or "", None)
        return user


class Attempts:
    """Failed sign-ins per key (``user:<name>``, ``address:<ip>``) and the lockouts they earn.

    The first ``FREE`` failures in a row cost nothing more than the wrong password's answer;
    each one after locks the key for ``FIRST_S`` doubled per failure, at most ``MOST_S``. A
    success clears the key. The keys held are bounded (``KEEP``, the oldest forgotten first),
    and a key quiet for ``FORGET_S`` is forgotten. Pure: the caller gives the time.
    """

    FREE = 5
    FIRST_S = 2.0
    MOST_S = 900.0
    KEEP = 10_000
    FORGET_S = 3600.0

    def __init__(self) -> None:
        self._failed: OrderedDict[str, tuple[int, float]] = OrderedDict()  # key -> (count, last)

    def wait_s(self, key: str, now: float) -> float:
        """How long ``key`` must still wait before its next try (0: it may try now)."""
        got = self._failed.get(key)
        if got is None:
            return 0.0
        count, last = got
        if now - last > self.FORGET_S:
            del self._failed[key]
            return 0.0
        if count < self.FREE:
            return 0.0
        lock = min(self.MOST_S, self.FIRST_S * 2 ** (count - self.FREE))
        return max(0.0, last + lock - now)

    def failed(self, key: str, now: float) -> None:
        count, _ = self._failed.pop(key, (0, now))
        self._failed[key] = (count + 1, now)
        while len(self._failed) > self.KEEP:
            self._failed.popitem(last=False)

    def succeeded(self, key: str) -> None:
        self._failed.pop(key, None)

    def __len__(self) -> int:
        return len(self._failed)
