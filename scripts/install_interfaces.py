"""Build the idpose_interfaces package (ament_cmake + rosidl) from the ROS wheels of a pip-only install
and install it into the Python environment running this script, so that
``python -c 'from idpose_interfaces.action import EstimatePoses'`` works with nothing sourced.

Usage: ``<venv>/bin/python scripts/install_interfaces.py`` (``./run`` does this once per install).

The ROS wheels (requirements-ros.txt) install a ROS prefix into the environment itself: ``share/`` for
CMake packages and the ament index, ``lib/`` for the C libraries, ``lib/python3.X/site-packages`` for
Python. Three things differ from a ROS installation, and the build fixes them up:

1. The wheels' CMake exports of the generated Python typesupport name the include directories of the
   manylinux build machine's Python (``/opt/python/cp311-cp311/...``: Python.h and numpy's headers).
   CMake refuses an imported target whose include directory does not exist, so the exports are
   rewritten, once, to this environment's own (``fix_cmake_exports``).
2. Nothing sets the variables a sourced ROS setup script would: rosidl finds its generators and
   typesupports through the ament index on ``AMENT_PREFIX_PATH``, CMake its packages on
   ``CMAKE_PREFIX_PATH``, and the generators must run on this environment's Python
   (``build_environment``, ``cmake_arguments``).
3. At run time, rosidl's C typesupport looks up the package's typesupport libraries on
   ``LD_LIBRARY_PATH`` (it opens them by path). The wheels' start-up hook (ros_wheels_bootstrapper)
   puts ``<prefix>/lib`` there for every Python started from the environment, which is why the
   libraries are installed into ``<prefix>/lib`` beside the wheels' own. An rpath lets the Python
   extension modules find the libraries they link without it.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import sysconfig
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "idpose_interfaces"
# The manylinux build's Python prefix, as the wheels' CMake exports spell it.
BUILD_PYTHON = re.compile(r"/opt/python/cp3\d+-cp3\d+(?P<rest>/include/python3\.\d+|/lib/python3\.\d+/site-packages)")
# Imported after the install, in a clean environment, to prove it works with nothing set up.
IMPORT_CHECK = "from idpose_interfaces.action import EstimatePoses; from idpose_interfaces.msg import ViewEstimate"


def local_path(rest: str) -> str:
    """This environment's counterpart of a path under the manylinux build's Python prefix."""
    paths = sysconfig.get_paths()
    return paths["include"] if rest.startswith("/include/") else paths["platlib"]


def fix_cmake_exports(prefix: Path) -> list[Path]:
    """Rewrite the build machine's Python include paths in ``prefix``'s CMake files to this environment's
    (fix-up 1); returns the files changed. Running it again changes nothing."""
    changed = []
    for path in sorted((prefix / "share").glob("*/cmake/*.cmake")):
        text = path.read_text()
        fixed = BUILD_PYTHON.sub(lambda match: local_path(match["rest"]), text)
        if fixed != text:
            path.write_text(fixed)
            changed.append(path)
    return changed


def prepend(value: str, existing: str | None) -> str:
    """``value`` first on a path list, the existing entries after it."""
    return os.pathsep.join([value, *(existing.split(os.pathsep) if existing else [])])


def build_environment(prefix: Path, base: Mapping[str, str] = os.environ) -> dict[str, str]:
    """``base`` with ``prefix`` first on the paths a sourced ROS setup would set for a build (fix-up 2)."""
    env = dict(base)
    for name in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH"):
        env[name] = prepend(str(prefix), env.get(name))
    env["PATH"] = prepend(str(Path(sys.executable).parent), env.get("PATH"))
    return env


def cmake_arguments(prefix: Path) -> list[str]:
    """CMake cache entries for building an interface package against ``prefix``'s ROS wheels: this Python for
    the generators and their extension modules, no tests, and the rpath from the extension modules
    (in site-packages) and the libraries (in lib/) to ``<install prefix>/lib`` (fix-ups 2 and 3)."""
    site = Path(sysconfig.get_paths(vars={"base": str(prefix), "platbase": str(prefix)})["purelib"])
    to_lib = os.path.relpath(prefix / "lib", site / "package")
    return [f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF",
            f"-DCMAKE_INSTALL_RPATH=$ORIGIN;$ORIGIN/{to_lib}"]


def clean_environment() -> dict[str, str]:
    """The environment of a fresh shell with nothing ROS set: no LD_LIBRARY_PATH, no setup script."""
    return {name: os.environ[name] for name in ("HOME", "LANG", "TMPDIR") if name in os.environ} | {
        "PATH": "/usr/bin:/bin"}


def run(command: list[str], env: Mapping[str, str], log: Path) -> None:
    """Run one build step, its output to ``log``; on failure, raise with the log's tail."""
    with log.open("a") as out:
        out.write(f"$ {shlex.join(command)}\n")
        out.flush()
        result = subprocess.run(command, env=env, stdout=out, stderr=subprocess.STDOUT)
    if result.returncode:
        tail = "".join(log.read_text().splitlines(keepends=True)[-40:])
        raise RuntimeError(f"`{shlex.join(command)}` failed ({result.returncode}); the end of its output:\n{tail}")


def install(package: Path, prefix: Path, build_dir: Path) -> None:
    """Configure, build and install ``package`` into ``prefix``, then import it in a clean environment;
    prints a line as each step starts."""
    env, build, log = build_environment(prefix), str(build_dir / "build"), build_dir / "build.log"
    steps = [
        ("configure", ["cmake", "-S", str(package), "-B", build, f"-DCMAKE_INSTALL_PREFIX={prefix}",
                       *cmake_arguments(prefix)], env),
        ("build", ["cmake", "--build", build, "--parallel", str(os.cpu_count() or 1)], env),
        ("install", ["cmake", "--install", build], env),
        ("import with nothing set up", [sys.executable, "-c", IMPORT_CHECK], clean_environment()),
    ]
    for number, (name, command, step_env) in enumerate(steps, start=1):
        print(f"install_interfaces: [{number}/{len(steps)}] {name}", flush=True)
        run(command, step_env, log)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--package", type=Path, default=PACKAGE, help="the interface package's folder")
    parser.add_argument("--prefix", type=Path, default=Path(sys.prefix),
                        help="the environment holding the ROS wheels, where the package is installed")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    fixed = fix_cmake_exports(args.prefix)
    print(f"install_interfaces: {len(fixed)} CMake exports pointed at this Python's include paths", flush=True)
    with tempfile.TemporaryDirectory(prefix="idpose_interfaces-") as build_dir:
        install(args.package, args.prefix, Path(build_dir))
    print(f"install_interfaces: {args.package.name} installed into {args.prefix} "
          f"in {time.perf_counter() - start:.1f} s", flush=True)


if __name__ == "__main__":
    main()
