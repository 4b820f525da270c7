"""Domain claims are exclusive across processes; the shm cleaner removes only dead files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from twin.errors import ConfigError
from twin.ros_isolation import (
    DOMAIN_ID_MAX,
    DOMAIN_ID_MIN,
    FASTDDS_PROFILE,
    RosIsolationError,
    clean_stale_fastdds_shm,
    isolated_ros_env,
    local_ros_defaults,
    ros_domain,
)

_CLAIM_SCRIPT = """
import sys, time
from pathlib import Path
from twin.ros_isolation import ros_domain
with ros_domain(lock_dir=Path(sys.argv[1])) as domain:
    print(domain.domain_id, flush=True)
    sys.stdin.read()
"""

_FLOCK_SCRIPT = """
import fcntl, sys
handle = open(sys.argv[1], "rb")
fcntl.flock(handle, fcntl.LOCK_SH if sys.argv[2] == "shared" else fcntl.LOCK_EX)
print("locked", flush=True)
sys.stdin.read()
"""


def test_isolated_env_sets_ros_variables_and_keeps_the_rest() -> None:
    base = {"PATH": "/usr/bin", "ROS_LOCALHOST_ONLY": "1", "ROS_DOMAIN_ID": "0"}
    env = isolated_ros_env(base, domain_id=42)
    assert env["ROS_DOMAIN_ID"] == "42"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert env["RMW_IMPLEMENTATION"] == "rmw_fastrtps_cpp"
    assert env["PATH"] == "/usr/bin"
    assert "ROS_LOCALHOST_ONLY" not in env
    assert base["ROS_DOMAIN_ID"] == "0"


def test_isolated_env_names_the_discovery_profile_unless_one_is_set() -> None:
    env = isolated_ros_env({}, domain_id=42)
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(FASTDDS_PROFILE)
    assert env["FASTDDS_DEFAULT_PROFILES_FILE"] == str(FASTDDS_PROFILE)
    own = isolated_ros_env({"FASTRTPS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"}, domain_id=42)
    assert own["FASTRTPS_DEFAULT_PROFILES_FILE"] == "/etc/mine.xml"
    assert "FASTDDS_DEFAULT_PROFILES_FILE" not in own


_PARTICIPANT = (
    "import rclpy\n"
    "rclpy.init()\n"
    "node = rclpy.create_node('profile_check')\n"
    "node.destroy_node()\n"
    "rclpy.shutdown()\n"
)


def _participant_log(env: dict[str, str]) -> str:
    done = subprocess.run(
        [sys.executable, "-c", _PARTICIPANT],
        check=True,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=60,
    )
    return done.stdout


def test_fast_dds_loads_the_discovery_profile_without_an_error(tmp_path: Path) -> None:
    # Fast DDS keeps going on its defaults after a profile it cannot parse and only logs it
    # (``XMLPARSER Error`` lines, on stdout), so a real participant is started and its log read.
    base = {k: v for k, v in os.environ.items() if not k.endswith("_DEFAULT_PROFILES_FILE")}
    with ros_domain(base) as domain:
        ros_env = domain.env
        assert ros_env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(FASTDDS_PROFILE)
        log = _participant_log(ros_env)
        assert "XMLPARSER" not in log, log
        bad = tmp_path / "bad.xml"
        bad.write_text(
            FASTDDS_PROFILE.read_text().replace(
                "<nanosec>500000000</nanosec>", "<nanosec>x</nanosec>"
            )
        )
        rejected = _participant_log({**ros_env, "FASTRTPS_DEFAULT_PROFILES_FILE": str(bad)})
    assert "XMLPARSER" in rejected  # so the check above would see a profile Fast DDS rejects


def test_local_defaults_fill_in_only_what_is_not_set() -> None:
    env: dict[str, str] = {"ROS_DOMAIN_ID": "7"}
    local_ros_defaults(env)
    assert env == {
        "ROS_DOMAIN_ID": "7",
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILE),
        "FASTDDS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILE),
    }
    own = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "FASTDDS_DEFAULT_PROFILES_FILE": "/x.xml"}
    kept = dict(own)
    local_ros_defaults(own)
    assert own == kept


def test_isolated_env_claims_one_domain_per_process() -> None:
    first = isolated_ros_env({})
    second = isolated_ros_env({})
    domain_id = int(first["ROS_DOMAIN_ID"])
    assert DOMAIN_ID_MIN <= domain_id <= DOMAIN_ID_MAX
    assert second["ROS_DOMAIN_ID"] == first["ROS_DOMAIN_ID"]


@pytest.mark.parametrize("bad", [-1, 233, 1.5, "7", True])
def test_bad_domain_id_is_rejected(bad: Any) -> None:
    with pytest.raises(ConfigError, match=r"ROS domain id"):
        isolated_ros_env({}, domain_id=bad)


def test_concurrent_processes_claim_distinct_domains(tmp_path: Path) -> None:
    claimers = [
        subprocess.Popen(
            [sys.executable, "-c", _CLAIM_SCRIPT, str(tmp_path)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for _ in range(6)
    ]
    try:
        ids = [int(proc.stdout.readline()) for proc in claimers if proc.stdout is not None]
        assert len(set(ids)) == 6
        assert all(DOMAIN_ID_MIN <= i <= DOMAIN_ID_MAX for i in ids)
        with (
            pytest.raises(RosIsolationError, match=rf"ROS domain id {ids[0]} is in use"),
            ros_domain({}, domain_id=ids[0], lock_dir=tmp_path),
        ):
            pass
    finally:
        for proc in claimers:
            proc.communicate("")
    with ros_domain({}, domain_id=ids[0], lock_dir=tmp_path) as domain:
        assert domain.env["ROS_DOMAIN_ID"] == str(ids[0])


def test_claims_are_released_when_the_holder_is_killed(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", _CLAIM_SCRIPT, str(tmp_path)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout is not None
    domain_id = int(holder.stdout.readline())
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    with ros_domain({}, domain_id=domain_id, lock_dir=tmp_path) as domain:
        assert domain.domain_id == domain_id


def test_all_domains_taken_is_a_clear_error(tmp_path: Path) -> None:
    from contextlib import ExitStack

    with ExitStack() as stack:
        ids = {
            stack.enter_context(ros_domain({}, lock_dir=tmp_path)).domain_id
            for _ in range(DOMAIN_ID_MAX - DOMAIN_ID_MIN + 1)
        }
        assert ids == set(range(DOMAIN_ID_MIN, DOMAIN_ID_MAX + 1))
        with pytest.raises(RosIsolationError, match=r"no free ROS domain id in 1\.\.101"):
            stack.enter_context(ros_domain({}, lock_dir=tmp_path))


def _touch_old(path: Path, age_s: float = 60.0) -> None:
    path.write_bytes(b"x")
    old_s = time.time() - age_s
    os.utime(path, (old_s, old_s))


def test_cleaner_removes_dead_files_and_keeps_live_ones(tmp_path: Path) -> None:
    stale_segment = ["fastrtps_0123456789abcdef", "fastrtps_0123456789abcdef_el"]
    stale_port = [
        "fastrtps_port7411",
        "fastrtps_port7411_el",
        "fastrtps_port7411_sl",
        "sem.fastrtps_port7411_mutex",
    ]
    stale_v3 = ["fastdds_fedcba9876543210", "fastdds_fedcba9876543210_el"]
    live_segment = ["fastrtps_aaaaaaaaaaaaaaaa", "fastrtps_aaaaaaaaaaaaaaaa_el"]
    live_port = ["fastrtps_port7413", "fastrtps_port7413_el", "fastrtps_port7413_sl"]
    young = ["fastrtps_bbbbbbbbbbbbbbbb", "fastrtps_bbbbbbbbbbbbbbbb_el"]
    unrelated = ["fastrtps_port7415", "lttng-ust-wait-6", "fastrtps_not_a_segment_el"]
    for name in stale_segment + stale_port + stale_v3 + live_segment + live_port + unrelated:
        _touch_old(tmp_path / name)
    for name in young:
        (tmp_path / name).write_bytes(b"x")
    holders = [
        subprocess.Popen(
            [sys.executable, "-c", _FLOCK_SCRIPT, str(tmp_path / name), mode],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for name, mode in [
            ("fastrtps_aaaaaaaaaaaaaaaa_el", "exclusive"),
            ("fastrtps_port7413_sl", "shared"),
        ]
    ]
    try:
        for holder in holders:
            assert holder.stdout is not None
            assert holder.stdout.readline().strip() == "locked"
        removed = clean_stale_fastdds_shm(tmp_path, min_age_s=2.0)
    finally:
        for holder in holders:
            holder.communicate("")

    remaining = {path.name for path in tmp_path.iterdir()}
    assert removed == len(stale_segment + stale_port + stale_v3)
    assert remaining == set(live_segment + live_port + young + unrelated)


def test_cleaner_on_missing_directory_removes_nothing(tmp_path: Path) -> None:
    assert clean_stale_fastdds_shm(tmp_path / "absent") == 0


def _mapped_shm_files(pid: int) -> set[str]:
    maps = Path(f"/proc/{pid}/maps").read_text(encoding="utf-8")
    return {Path(line.split()[-1]).name for line in maps.splitlines() if "/dev/shm/fast" in line}


@pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="no /dev/shm on this platform")
def test_cleaner_removes_a_killed_participants_files_only(nodes: Any, ros_env_factory: Any) -> None:
    victim = nodes.start(ros_env_factory(), "idle")
    survivor = nodes.start(ros_env_factory(), "idle")
    victim_files = _mapped_shm_files(victim.pid)
    survivor_files = _mapped_shm_files(survivor.pid)
    assert victim_files, "the Fast DDS participant mapped no shared memory"
    assert survivor_files
    own_victim_files = victim_files - survivor_files

    victim.process.send_signal(signal.SIGKILL)
    victim.process.wait()
    shm = Path("/dev/shm")
    assert any((shm / name).exists() for name in own_victim_files)
    removed = clean_stale_fastdds_shm(min_age_s=0.0)

    assert removed >= 1
    assert not [name for name in own_victim_files if (shm / name).exists()]
    assert all((shm / name).exists() for name in survivor_files)
    assert survivor.process.poll() is None
    assert survivor.stop() == 0
