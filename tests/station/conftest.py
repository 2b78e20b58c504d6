"""Fixtures of the station tests: a real PostgreSQL server in a temporary folder.

The server is Debian's `postgresql` (initdb + pg_ctl), listening on a Unix socket in the
temporary folder and on 127.0.0.1 at a free port. Without it the PostgreSQL tests skip,
unless ZEROCAL_REQUIRE_POSTGRES is set (CI), where they fail.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from tests.station.test_station import StationProcess


def _postgres_bin() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    if found:
        return Path(found[-1]).parent
    initdb = shutil.which("initdb")
    return Path(initdb).parent if initdb else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="session")
def postgres_url() -> Iterator[str]:
    bindir = _postgres_bin()
    if bindir is None:
        if os.environ.get("ZEROCAL_REQUIRE_POSTGRES"):
            pytest.fail("PostgreSQL is not installed (apt-get install -y postgresql)")
        pytest.skip("PostgreSQL is not installed (apt-get install -y postgresql)")
    folder = Path(tempfile.mkdtemp(prefix="zerocal-pg-"))
    data = folder / "data"
    as_user: list[str] = []
    if os.geteuid() == 0:  # PostgreSQL refuses to run as root
        user = "postgres"
        try:
            entry = pwd.getpwnam(user)
        except KeyError:
            pytest.fail("running as root needs the 'postgres' system user")
        os.chown(folder, entry.pw_uid, entry.pw_gid)
        as_user = ["runuser", "-u", user, "--"]
    port = _free_port()
    subprocess.run([*as_user, str(bindir / "initdb"), "-D", str(data), "-U", "zerocal",
                    "--auth=trust", "-E", "UTF8"], check=True, capture_output=True)
    subprocess.run([*as_user, str(bindir / "pg_ctl"), "-D", str(data), "-l",
                    str(folder / "server.log"), "-w", "-o",
                    f"-k {folder} -p {port} -c listen_addresses=127.0.0.1", "start"],
                   check=True, capture_output=True)
    try:
        subprocess.run([*as_user, str(bindir / "createdb"), "-h", str(folder), "-p", str(port),
                        "-U", "zerocal", "archive"], check=True, capture_output=True)
        yield f"postgresql://zerocal@127.0.0.1:{port}/archive"
    finally:
        subprocess.run([*as_user, str(bindir / "pg_ctl"), "-D", str(data), "-m", "fast",
                        "stop"], capture_output=True)
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(params=["sqlite", "postgresql"])
def archive_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """The same tests against SQLite (a file) and PostgreSQL (a real server; each test in
    its own fresh database)."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'archive.db'}"
        return
    base = request.getfixturevalue("postgres_url")
    import sqlalchemy as sa

    name = f"t{os.getpid()}_{abs(hash(request.node.nodeid)) % 10**9}"
    admin = sa.create_engine(base.replace("postgresql://", "postgresql+psycopg://"),
                             isolation_level="AUTOCOMMIT")
    with admin.connect() as connection:
        connection.exec_driver_sql(f'CREATE DATABASE "{name}"')
    admin.dispose()
    yield base.rsplit("/", 1)[0] + f"/{name}"


REPO = Path(__file__).resolve().parents[2]


def hostpc_command(*args: str) -> list[str]:
    import sys

    return [sys.executable, "-m", "hostpc.cli.main", *args]


@pytest.fixture(scope="session")
def fast_rig(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A stereo rig calibrated once from the simulator's chessboard views (the packaged
    default camera), so station runs skip the 20-view rig calibration."""
    folder = tmp_path_factory.mktemp("rig")
    run = subprocess.run(hostpc_command("calibrate", "--robot", "sim", "--poses", "8",
                                        "--verify-poses", "0", "--no-push", "--no-report",
                                        "--out", str(folder / "run")),
                         cwd=REPO, capture_output=True, text=True, timeout=300)
    assert (folder / "run" / "rig.json").exists(), run.stderr[-2000:]
    return folder / "run" / "rig.json"


@pytest.fixture(scope="session")
def sim_run_dir(tmp_path_factory: pytest.TempPathFactory, fast_rig: Path) -> Path:
    """One finished, pushed and verified simulated calibration run folder."""
    folder = tmp_path_factory.mktemp("simrun") / "run"
    run = subprocess.run(hostpc_command("calibrate", "--robot", "sim", "--poses", "12",
                                        "--verify-poses", "4", "--rig", str(fast_rig),
                                        "--no-report", "--out", str(folder)),
                         cwd=REPO, capture_output=True, text=True, timeout=300)
    assert (folder / "result.json").exists(), run.stderr[-2000:]
    return folder


StationFactory = Callable[..., tuple["StationProcess", dict[str, Any]]]


@pytest.fixture
def make_station(tmp_path: Path, fast_rig: Path) -> Iterator[StationFactory]:
    """A station process on a config of a simulated cell (known target, 12 + 4 poses, the
    fast rig), `overrides` winning over its keys, `calibrate_args` added after the rig's;
    each started station is killed at the end if still running."""
    import signal

    import yaml

    from tests.station.test_station import StationProcess, _free_port

    started: list[StationProcess] = []

    def make(**overrides: Any) -> tuple[StationProcess, dict[str, Any]]:
        extra = list(overrides.pop("calibrate_args", []))
        config = {"station": "eol-2", "robot": "sim", "known": "target", "poses": 12,
                  "verify_poses": 4, "calibrate_args": ["--rig", str(fast_rig), *extra],
                  "db": f"sqlite:///{tmp_path / 'archive.db'}",
                  "runs_dir": str(tmp_path / "runs"),
                  "modbus": {"host": "127.0.0.1", "port": _free_port()}, **overrides}
        path = tmp_path / "station.yaml"
        path.write_text(yaml.safe_dump(config))
        process = StationProcess(path, tmp_path / "station.log")
        process.start()
        started.append(process)
        return process, config

    yield make
    for process in started:
        if process.process is not None and process.process.poll() is None:
            process.stop(signal.SIGKILL)
