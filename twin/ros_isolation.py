"""Keep concurrent ROS 2 runs apart: one DDS domain each, localhost only, no stale shared memory.

Every run and every test gets its own ``ROS_DOMAIN_ID`` in 1..101, so parallel runs on one
machine never see each other's topics. A domain is claimed by holding an exclusive ``flock`` on
``<tmp>/cdw_twin_ros_domains/domain_<id>.lock``; the kernel drops the lock when its holder exits,
so a crashed run never leaks a domain. Pure standard library; rclpy is never imported here.

Typical use::

    with ros_domain() as domain:                      # lock held until the block ends
        subprocess.run(cmd, env=domain.env, check=True)

    env = isolated_ros_env()                          # lock held until this process exits

Child processes also get ``FASTRTPS_DEFAULT_PROFILES_FILE`` (and Fast DDS 3's
``FASTDDS_DEFAULT_PROFILES_FILE``) set to ``twin/fastdds_profile.xml`` unless the environment
already names a profile: participants announce themselves more often, so a controller that
starts seconds after the twin matches in a fraction of a second instead of waiting up to 3 s for
Fast DDS's next periodic announcement (see the file for the figures).

Fast DDS puts its shared-memory transport in ``/dev/shm``: per segment ``fastrtps_<16 chars>``
plus a lock file ``..._el``, per port ``fastrtps_port<n>`` plus ``..._el``/``..._sl`` and a
semaphore ``sem.fastrtps_port<n>_mutex`` (``fastdds_`` instead of ``fastrtps_`` in Fast DDS 3).
The owner holds an ``flock`` on the lock files while it lives, so a lock file that can be locked
exclusively belongs to a dead process (the rule of eProsima's own ``fastdds shm clean``).
:func:`clean_stale_fastdds_shm` removes exactly those, never a file some process still locks.
"""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import os
import random
import re
import tempfile
import time
from collections.abc import Iterator, Mapping, MutableMapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from twin.errors import CdwTwinError, ConfigError

DOMAIN_ID_MIN = 1
DOMAIN_ID_MAX = 101
MAX_VALID_DOMAIN_ID = 232
RMW_IMPLEMENTATION = "rmw_fastrtps_cpp"
DEFAULT_SHM_DIR = Path("/dev/shm")
DEFAULT_LOCK_DIR = Path(tempfile.gettempdir()) / "cdw_twin_ros_domains"

_LOCK_FILE_RE = re.compile(
    r"^(?P<base>(?:fastrtps|fastdds)_(?:port\d{1,5}|[0-9a-z]{16}))_(?:el|sl)$"
)
_DROPPED_VARIABLES = ("ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS")
FASTDDS_PROFILE = Path(__file__).with_name("fastdds_profile.xml")
"""The participant profile isolated runs use unless the environment names another."""
_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


class RosIsolationError(CdwTwinError):
    """No ROS domain could be claimed for an isolated run."""


@dataclass(frozen=True, kw_only=True)
class RosDomain:
    """A claimed ROS domain: its id and the environment that selects it.

    ``env`` is a full process environment (the base environment plus the ROS variables) to pass
    as ``env=`` to ``subprocess``.
    """

    domain_id: int
    env: dict[str, str] = field(repr=False)
    lock_path: Path


def ros_variables(domain_id: int) -> dict[str, str]:
    """The ROS variables of an isolated run on ``domain_id``."""
    _check_domain_id(domain_id)
    return {
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "RMW_IMPLEMENTATION": RMW_IMPLEMENTATION,
    }


def _check_domain_id(domain_id: int) -> None:
    if isinstance(domain_id, bool) or not isinstance(domain_id, int):
        msg = f"ROS domain id must be an int, got {domain_id!r}"
        raise ConfigError(msg)
    if not 0 <= domain_id <= MAX_VALID_DOMAIN_ID:
        msg = f"ROS domain id {domain_id} is outside 0..{MAX_VALID_DOMAIN_ID}"
        raise ConfigError(msg)


def _add_profile(env: MutableMapping[str, str]) -> None:
    if not any(env.get(name) for name in _PROFILE_VARIABLES):
        env.update(dict.fromkeys(_PROFILE_VARIABLES, str(FASTDDS_PROFILE)))


def local_ros_defaults(env: MutableMapping[str, str] | None = None) -> None:
    """Defaults for a node started by hand (``cdw-twin twin-node``, ``record``), before rclpy.

    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and the Fast DDS profile, each only where
    ``env`` (default ``os.environ``) does not set it already; the domain is left as it is.
    A controller that joins later then matches within one of this node's announcements.
    """
    target = os.environ if env is None else env
    target.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    _add_profile(target)


def _environment(base: Mapping[str, str] | None, domain_id: int) -> dict[str, str]:
    env = dict(os.environ if base is None else base)
    for name in _DROPPED_VARIABLES:
        env.pop(name, None)
    env.update(ros_variables(domain_id))
    _add_profile(env)
    return env


def _try_lock(path: Path) -> IO[str] | None:
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        handle = path.open("a")
    except PermissionError:
        return None
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        return None
    return handle


def claim_domain(lock_dir: Path = DEFAULT_LOCK_DIR) -> tuple[int, IO[str]]:
    """Claim a free domain id in 1..101; returns it and the open, locked lock file.

    The id stays claimed until the returned file is closed (or the process exits). Ids are tried
    from a random start so concurrent claimers rarely contend for the same lock.
    """
    n_ids = DOMAIN_ID_MAX - DOMAIN_ID_MIN + 1
    start = random.SystemRandom().randrange(n_ids)
    for offset in range(n_ids):
        domain_id = DOMAIN_ID_MIN + (start + offset) % n_ids
        handle = _try_lock(lock_dir / f"domain_{domain_id}.lock")
        if handle is not None:
            handle.seek(0)
            handle.truncate()
            handle.write(f"{os.getpid()}\n")
            handle.flush()
            return domain_id, handle
    msg = (
        f"no free ROS domain id in {DOMAIN_ID_MIN}..{DOMAIN_ID_MAX}: "
        f"every lock under {lock_dir} is held by a running process"
    )
    raise RosIsolationError(msg)


@contextlib.contextmanager
def ros_domain(
    base: Mapping[str, str] | None = None,
    *,
    domain_id: int | None = None,
    lock_dir: Path = DEFAULT_LOCK_DIR,
) -> Iterator[RosDomain]:
    """Claim a ROS domain for the duration of the ``with`` block.

    With ``domain_id`` given, that id is claimed or :class:`RosIsolationError` is raised when
    another process holds it. ``base`` is the environment to extend (default ``os.environ``).
    """
    if domain_id is None:
        claimed_id, handle = claim_domain(lock_dir)
    else:
        _check_domain_id(domain_id)
        claimed_id = domain_id
        maybe_handle = _try_lock(lock_dir / f"domain_{domain_id}.lock")
        if maybe_handle is None:
            msg = f"ROS domain id {domain_id} is in use (locked under {lock_dir})"
            raise RosIsolationError(msg)
        handle = maybe_handle
    lock_path = lock_dir / f"domain_{claimed_id}.lock"
    try:
        yield RosDomain(
            domain_id=claimed_id, env=_environment(base, claimed_id), lock_path=lock_path
        )
    finally:
        handle.close()


_process_domain: tuple[int, IO[str]] | None = None


def _close_process_domain() -> None:
    if _process_domain is not None:
        _process_domain[1].close()


def isolated_ros_env(
    base: Mapping[str, str] | None = None, domain_id: int | None = None
) -> dict[str, str]:
    """An environment for an isolated ROS 2 run.

    Sets ``ROS_DOMAIN_ID``, ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and
    ``RMW_IMPLEMENTATION=rmw_fastrtps_cpp`` on a copy of ``base`` (default ``os.environ``), the
    Fast DDS profile (see the module) unless ``base`` names one, and drops
    ``ROS_LOCALHOST_ONLY``/``ROS_STATIC_PEERS``. With ``domain_id=None`` the id is claimed
    once per process and held until the process exits; use :func:`ros_domain` for a shorter claim.
    An explicit ``domain_id`` is used as given, without a claim.
    """
    global _process_domain  # noqa: PLW0603
    if domain_id is None:
        if _process_domain is None:
            _process_domain = claim_domain()
            atexit.register(_close_process_domain)
        domain_id = _process_domain[0]
    return _environment(base, domain_id)


@contextlib.contextmanager
def _locked_all(paths: list[Path]) -> Iterator[bool]:
    """Hold an exclusive lock on every path; yields False if any is locked or missing."""
    with contextlib.ExitStack() as stack:
        for path in paths:
            try:
                handle = stack.enter_context(path.open("rb"))
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except (BlockingIOError, FileNotFoundError):
                yield False
                return
        yield True


def _unlink(path: Path) -> int:
    try:
        path.unlink()
    except FileNotFoundError:
        return 0
    return 1


def clean_stale_fastdds_shm(shm_dir: Path = DEFAULT_SHM_DIR, *, min_age_s: float = 2.0) -> int:
    """Remove Fast DDS shared-memory files whose owning process is dead; returns the file count.

    A segment or port is stale when none of its lock files (``_el``, ``_sl``) is locked by any
    process. Its data file, lock files and (ports) ``sem.<name>_mutex`` are removed. Files
    younger than ``min_age_s`` are left alone, since a starting participant creates its files
    an instant before it locks them. Files a live process locks are never touched.
    """
    try:
        names = os.listdir(shm_dir)
    except FileNotFoundError:
        return 0
    locks_by_base: dict[str, list[str]] = {}
    for name in names:
        match = _LOCK_FILE_RE.match(name)
        if match is not None:
            locks_by_base.setdefault(match.group("base"), []).append(name)
    now_s = time.time()
    removed = 0
    for base, lock_names in sorted(locks_by_base.items()):
        lock_paths = [shm_dir / name for name in sorted(lock_names)]
        if any(_is_recent(path, now_s, min_age_s) for path in lock_paths):
            continue
        with _locked_all(lock_paths) as all_free:
            if not all_free:
                continue
            removed += _unlink(shm_dir / base)
            if "_port" in base:
                removed += _unlink(shm_dir / f"sem.{base}_mutex")
            for path in lock_paths:
                removed += _unlink(path)
    return removed


def _is_recent(path: Path, now_s: float, min_age_s: float) -> bool:
    try:
        return now_s - path.stat().st_mtime < min_age_s
    except FileNotFoundError:
        return True
