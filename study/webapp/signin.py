"""Researcher sign-in, hardened: the password kept as a scrypt hash, lockout with exponential back-off after
repeated failures (per account name and per client address), sessions held on the server (a cookie only names
one, so logout and a password change end it for good), and CSRF tokens.

Everything here is in memory of the server process: a restart ends every session and forgets the failure counts
(the password is read again from ``PEDAS_SURVEY_PASSWORD``).
"""
from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

from study.common.errors import UserError

MIN_NEW_PASSWORD = 10  # characters of a password set on the console
MAX_KEYS = 10_000      # failure records kept before stale ones are dropped


class WrongPassword(UserError):
    """A password change whose current password is wrong (counted by the throttle like a failed sign-in)."""


@dataclass(frozen=True)
class SignInSettings:
    """How sign-in is guarded.

    * ``max_failures`` wrong passwords in a row for one account name, or ``max_failures_per_address`` from one
      client address, lock that name / address for ``lockout_s`` seconds; each further lockout of the same key
      doubles the time (back-off), up to ``max_lockout_s``. A key with no failure for ``forget_s`` starts afresh.
    * ``session_idle_s``: a session unused this long has ended.
    * ``trust_proxy``: number of reverse proxies in front of the server whose ``X-Forwarded-For`` and
      ``X-Forwarded-Proto`` are believed (0 = none: the socket's address and scheme count).
    * ``secure_cookies``: "auto" = the cookie gets ``Secure`` when the request came over HTTPS (directly or, with
      ``trust_proxy``, as the proxy says); "always" = always.
    """

    max_failures: int = 5
    max_failures_per_address: int = 20
    lockout_s: float = 30.0
    max_lockout_s: float = 900.0
    forget_s: float = 3600.0
    session_idle_s: float = 12 * 3600.0
    trust_proxy: int = 0
    secure_cookies: str = "auto"

    def __post_init__(self) -> None:
        if self.secure_cookies not in ("auto", "always"):
            raise UserError(f"secure_cookies must be auto or always, not {self.secure_cookies!r}")
        if self.max_failures < 1 or self.max_failures_per_address < 1 or self.trust_proxy < 0:
            raise UserError("sign-in limits must be >= 1 and trust_proxy >= 0")


# ---------------------------------------------------------------------------------------------- passwords
_SCRYPT = {"n": 2 ** 14, "r": 8, "p": 1}  # 16 MiB and ~0.1 s per check: slows guessing
CHECKS_AT_ONCE = 2  # password checks running in parallel (a burst of sign-ins queues: memory stays flat)


def hash_password(password: str, salt: bytes | None = None) -> str:
    """``scrypt$<salt hex>$<hash hex>`` of `password` (n=2^14, r=8, p=1, 32-byte key)."""
    salt = salt if salt is not None else secrets.token_bytes(16)
    key = hashlib.scrypt(password.encode("utf-8"), salt=salt, dklen=32, **_SCRYPT)
    return f"scrypt${salt.hex()}${key.hex()}"


def check_password(password: str, stored: str) -> bool:
    """True when `password` matches the :func:`hash_password` string `stored` (constant-time compare)."""
    _, salt, _ = stored.split("$")
    return hmac.compare_digest(hash_password(password, bytes.fromhex(salt)), stored)


# ---------------------------------------------------------------------------------------------- lockout
@dataclass
class _Key:
    failures: int = 0
    lockouts: int = 0
    locked_until: float = 0.0
    last_failure: float = 0.0


class Throttle:
    """Failed sign-ins per key ("account:<name>", "address:<ip>") with lockout and doubling back-off."""

    def __init__(self, settings: SignInSettings, clock: Callable[[], float] = time.monotonic) -> None:
        self.settings, self.clock = settings, clock
        self._keys: dict[str, _Key] = {}
        self._lock = threading.Lock()

    def _limit(self, key: str) -> int:
        s = self.settings
        return s.max_failures_per_address if key.startswith("address:") else s.max_failures

    def _stale(self, k: _Key, now: float) -> bool:
        return k.locked_until <= now and now - k.last_failure > self.settings.forget_s

    def _get(self, key: str, now: float) -> _Key:
        k = self._keys.get(key)
        if k is None or self._stale(k, now):
            k = self._keys[key] = _Key()
        return k

    def locked_for(self, keys: list[str]) -> float:
        """Seconds until every one of `keys` may try again (0 = may try now)."""
        now = self.clock()
        with self._lock:
            return self._wait(keys, now)

    def _wait(self, keys: list[str], now: float) -> float:
        return max([0.0] + [self._keys[key].locked_until - now for key in keys if key in self._keys])

    def attempt(self, keys: list[str]) -> float:
        """Before a password is checked: the seconds to wait when a key is locked (nothing counted), else 0 with
        the attempt already counted as a failure of every key (:meth:`succeeded` forgets it). Checked and counted
        under one lock, so parallel guesses cannot all pass the check before any is counted: at most the limit's
        number of passwords is ever checked per key and lockout."""
        now = self.clock()
        with self._lock:
            wait = self._wait(keys, now)
            if wait <= 0:
                self._count(keys, now)
            return wait

    def failed(self, keys: list[str]) -> None:
        """Count one failure for each key; a key reaching its limit is locked (back-off doubles per lockout)."""
        with self._lock:
            self._count(keys, self.clock())

    def _count(self, keys: list[str], now: float) -> None:
        s = self.settings
        for key in keys:
            k = self._get(key, now)
            k.failures += 1
            k.last_failure = now
            if k.failures >= self._limit(key):
                k.locked_until = now + min(s.lockout_s * 2 ** k.lockouts, s.max_lockout_s)
                k.lockouts += 1
                k.failures = 0
        if len(self._keys) > MAX_KEYS:  # many names tried: forget the stale ones (memory stays bounded)
            self._keys = {key: k for key, k in self._keys.items() if not self._stale(k, now)}

    def succeeded(self, keys: list[str]) -> None:
        with self._lock:
            for key in keys:
                self._keys.pop(key, None)


# ---------------------------------------------------------------------------------------------- sessions
@dataclass
class Session:
    """One signed-in researcher: the name recorded as the audit-log actor, the CSRF token of every form."""

    name: str
    csrf: str = field(default_factory=lambda: secrets.token_urlsafe(24))
    last_seen: float = 0.0
    refill: dict[str, str] = field(default_factory=dict)  # a refused form's values, shown once (kept server-side)


class Sessions:
    """Server-side sessions by random id; the cookie carries only the id (signed by Flask)."""

    def __init__(self, idle_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.idle_s, self.clock = idle_s, clock
        self._by_id: dict[str, Session] = {}
        self._lock = threading.Lock()

    def create(self, name: str) -> str:
        sid = secrets.token_urlsafe(32)
        with self._lock:
            self._by_id[sid] = Session(name, last_seen=self.clock())
        return sid

    def get(self, sid: str | None) -> Session | None:
        """The live session `sid` names (its idle time restarts), or None."""
        if not isinstance(sid, str):
            return None
        now = self.clock()
        with self._lock:
            s = self._by_id.get(sid)
            if s is None:
                return None
            if now - s.last_seen > self.idle_s:
                del self._by_id[sid]
                return None
            s.last_seen = now
            return s

    def end(self, sid: str | None) -> None:
        with self._lock:
            self._by_id.pop(sid, None)

    def end_all(self) -> int:
        """End every session (a password change); how many there were."""
        with self._lock:
            n = len(self._by_id)
            self._by_id.clear()
        return n


# ---------------------------------------------------------------------------------------------- the whole
class SignIn:
    """The server's sign-in state: password hash, throttle, sessions."""

    def __init__(self, password: str, settings: SignInSettings | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not password:
            raise UserError("a researcher password is required")
        self.settings = settings or SignInSettings()
        self._hash = hash_password(password)
        self._lock = threading.Lock()
        self._checks = threading.BoundedSemaphore(CHECKS_AT_ONCE)
        self.throttle = Throttle(self.settings, clock)
        self.sessions = Sessions(self.settings.session_idle_s, clock)

    @staticmethod
    def keys(name: str, address: str | None) -> list[str]:
        return [f"account:{name.strip().casefold()}", f"address:{address or '?'}"]

    def check(self, password: str) -> bool:
        with self._lock:
            stored = self._hash
        with self._checks:
            return check_password(password, stored)

    def change_password(self, current: str, new: str, confirm: str) -> None:
        """Set a new password and end every session; UserError (nothing changed) when `current` is wrong
        (:class:`WrongPassword`), the two new ones differ or the new one is shorter than MIN_NEW_PASSWORD characters."""
        if not self.check(current):
            raise WrongPassword("The current password is wrong.")
        if new != confirm:
            raise UserError("The two new passwords differ.")
        if len(new) < MIN_NEW_PASSWORD:
            raise UserError(f"The new password needs at least {MIN_NEW_PASSWORD} characters.")
        with self._lock:
            self._hash = hash_password(new)
        self.sessions.end_all()
