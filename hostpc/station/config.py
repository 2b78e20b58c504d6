"""The station config file (YAML or JSON), validated with pydantic at the file edge.

    station: cell-7                  # name stored with every archived run
    robot: 192.168.1.10              # controller address, or `sim` (a simulated robot per run)
    method: stereo_target
    effects: null                    # as `hostpc calibrate --effects`
    known: null                      # as `hostpc calibrate --known`
    require_joints: all              # as `--require-joints` (null: none); a required joint
                                     # not calibrated is FAIL, result code 7
    swapped: null                    # as `--swapped` (e.g. J3 after its motor swap)
    swap_limit: null                 # as `--swap-limit` (deg; null: 45)
    poses: 60
    verify_poses: 10
    calibrate_args: []               # further `hostpc calibrate` options, verbatim
    db: sqlite:///station.db         # or postgresql://USER@HOST/DB
    runs_dir: station-runs
    modbus: {host: 127.0.0.1, port: 5020}
    http: null                       # e.g. 127.0.0.1:8080 for the live page
    resume_attempts: 2               # a run whose link dropped is resumed this often
    sim: {scenario: null, scenarios_by_serial: {}}

The controller token comes from the environment (ZEROCAL_TOKEN) or `calibrate_args`'
`--token-file`, never from this file.
"""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from hostpc.errors import InputError
from hostpc.input_files import CONFIG, read_input_text


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ModbusEndpoint(_Strict):
    host: str = "127.0.0.1"
    port: int = Field(default=5020, ge=0, le=65535)


class SimCell(_Strict):
    """With `robot: sim`: each robot is a simulated world seeded by its serial number;
    `scenario` is the base scenario file, `scenarios_by_serial` names a scenario per
    serial (paths relative to the config file)."""

    scenario: str | None = None
    scenarios_by_serial: dict[str, str] = Field(default_factory=dict)


class StationConfig(_Strict):
    station: str = Field("station", min_length=1, max_length=64)
    robot: str = Field(..., min_length=1)
    driver: str = "zerocal"
    method: str = "stereo_target"
    effects: str | None = None
    known: str | None = None
    require_joints: str | None = "all"
    swapped: str | None = None
    swap_limit: float | None = Field(None, gt=0.0, le=180.0)
    poses: int = Field(60, ge=4, le=10000)
    verify_poses: int = Field(10, ge=0, le=1000)
    calibrate_args: list[str] = Field(default_factory=list)
    db: str = "sqlite:///station.db"
    runs_dir: str = "station-runs"
    modbus: ModbusEndpoint = ModbusEndpoint()
    http: str | None = None
    resume_attempts: int = Field(2, ge=0, le=10)
    sim: SimCell = SimCell()
    base_dir: str = "."

    @field_validator("http")
    @classmethod
    def _host_port(cls, value: str | None) -> str | None:
        if value is not None:
            http_address(value)
        return value

    def http_address(self) -> tuple[str, int] | None:
        """`http` as (host, port), or None."""
        return None if self.http is None else http_address(self.http)

    def database_url(self) -> str:
        """`db` with a relative SQLite path taken relative to the config file's folder."""
        prefix = "sqlite:///"
        if self.db.startswith(prefix) and not self.db.startswith(prefix + "/"):
            return prefix + str(self.path(self.db[len(prefix):]).resolve())
        return self.db

    def path(self, value: str) -> Path:
        """`value` relative to the config file's folder."""
        candidate = Path(value).expanduser()
        return candidate if candidate.is_absolute() else Path(self.base_dir) / candidate


def http_address(text: str) -> tuple[str, int]:
    """HOST:PORT as (host, port); ValueError otherwise."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)


def load_station_config(path: str | Path, *, db: str | None = None,
                        modbus: tuple[str, int] | None = None) -> StationConfig:
    """Read and validate a station config; `db` and `modbus` (host, port), from the
    command line, win over the file's."""
    file = Path(path)
    try:
        data = yaml.safe_load(read_input_text(file, CONFIG))  # regular file, bounded
    except (OSError, yaml.YAMLError) as exc:
        raise InputError(f"{file}: cannot read station config ({str(exc).splitlines()[0]})"
                         ) from None
    if not isinstance(data, dict):
        raise InputError(f"{file}: station config must be a mapping")
    data = dict(data)
    if db is not None:
        data["db"] = db
    if modbus is not None:
        data["modbus"] = {"host": modbus[0], "port": modbus[1]}
    data.setdefault("base_dir", str(file.resolve().parent))
    try:
        return StationConfig.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise InputError(f"{file}: {where}: {first['msg']}") from None
