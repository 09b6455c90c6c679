"""A process ``lunaris up`` starts dies with it (SPEC §13e: a service never outlives its
supervisor), whatever its loop is doing.

``lunaris up`` names itself in :data:`SUPERVISOR_ENV`; :func:`follow_supervisor`, the first
thing the ``lunaris`` command line does, then makes the process follow it:

1. The kernel's parent-death signal (``prctl(PR_SET_PDEATHSIG, SIGTERM)``, Linux): when the
   supervisor dies, even by kill -9, the service is sent SIGTERM, stops as on Ctrl-C (its
   state saved, its session closed). Set here, in the child, not in ``up``'s ``preexec_fn``:
   ``up`` runs the router's threads, and Python code between fork and exec in a process
   with threads can deadlock on a lock another thread held at the fork.
2. The classic race: the supervisor may die between the fork and the ``prctl``; the child,
   already given to another parent, would never hear of it. So the parent is checked right
   after: not the supervisor any more, the process exits at once.
3. A last resort, on a thread of its own: ``GRACE_S`` after the supervisor is gone, a
   process still there (a stop that hangs: a session closing on a dead router, a wait that
   a signal broke) ends with ``os._exit``. The thread sleeps with the GIL released, so a
   main thread stuck in a C wait does not hold it back.

Elsewhere than Linux there is no parent-death signal: the service's own watch of its parent
(:meth:`common.runtime.Runtime.watch_parent`, every 0.5 s) stops it, and 3. still holds.
The variable is taken out of the environment, so the processes this one starts (the
console's recorder) are not taken for the supervisor's.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

__all__ = ["GRACE_S", "SUPERVISOR_ENV", "follow_supervisor", "supervisor"]

SUPERVISOR_ENV = "LUNARIS_SUPERVISOR_PID"  # set by `lunaris up` to its pid
GRACE_S = 5.0  # a process still there so long after its supervisor is gone is ended [s]
WATCH_S = 0.25  # how often the last resort looks at the parent [s]
PR_SET_PDEATHSIG = 1  # prctl(2)

_supervisor: int | None = None


def supervisor() -> int | None:
    """The pid of the ``lunaris up`` this process follows, if it follows one."""
    return _supervisor


def follow_supervisor() -> int | None:
    """Die with the supervisor :data:`SUPERVISOR_ENV` names, as the module says; its pid, or
    None if none is named. Exits at once (status 0) if it is no longer this process's parent."""
    global _supervisor
    text = os.environ.pop(SUPERVISOR_ENV, "")
    if not text.isdigit():
        return None
    pid = int(text)
    _parent_death_signal(signal.SIGTERM)
    if os.getppid() != pid:  # it died before the prctl: the signal will never come
        print(f"lunaris: supervisor {pid} is gone (before this process started); exiting",
              file=sys.stderr, flush=True)
        raise SystemExit(0)
    _supervisor = pid
    threading.Thread(target=_last_resort, args=(pid,), name="supervisor-gone", daemon=True).start()
    return pid


def _parent_death_signal(sig: int) -> bool:
    """``prctl(PR_SET_PDEATHSIG, sig)``; whether the kernel took it (Linux only)."""
    if not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
        errno = ctypes.get_errno()
        print(f"lunaris: prctl(PR_SET_PDEATHSIG) failed: {os.strerror(errno)}; the watch of "
              "the parent stands in", file=sys.stderr, flush=True)
        return False
    return True


def _last_resort(pid: int) -> None:
    while os.getppid() == pid:
        time.sleep(WATCH_S)
    time.sleep(GRACE_S)  # the parent-death signal's (or the watch's) stop, given its time
    print(f"lunaris: supervisor {pid} gone {GRACE_S:g} s ago and this process still there; "
          "ending it", file=sys.stderr, flush=True)
    os._exit(1)
