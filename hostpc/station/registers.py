"""The station's Modbus register map (holding registers, 16 bit, 0-based addresses).

The PLC writes COMMAND, SERIAL and MODEL; everything else is read-only to it. STATE is
PASS only for a run whose outcome verdict is PASS (pushed, verified, every required joint
calibrated); any other finished outcome is FAIL with RESULT_CODE its exit code (5 refused,
6 verification failed, 7 a required joint not calibrated, 0 not pushed / rolled back: see
OUTCOME_FLAGS). Strings are ASCII, two characters per register (high byte first),
NUL-padded. 32-bit values span two registers, high word first. A run that did not PASS
says why in REASON_CODE (Reason below) and REASON (the one-line reason, as in the station
log, the live page and the archive). docs/station.md carries the same table for the PLC
programmer.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

from hostpc.archive.records import OutcomeFigures

N_REGISTERS = 96

COMMAND = 0            # PLC writes: 1 start, 2 abort, 3 acknowledge; cleared when read
STATE = 1              # State below
RESULT_CODE = 2        # `hostpc calibrate`'s exit code of the last run (0 = pass)
HEARTBEAT = 3          # +1 every second while the station lives (wraps at 65535)
PROGRESS = 4           # 0..100 % of the running calibration
RUN_COUNTER = 5        # +1 per started run
LARGEST_CORRECTION = 6  # 6-7: int32, largest pushed correction in 0.0001 deg
VERIFY_STATISTIC = 8   # 8-9: uint32, verification statistic x 1000
VERIFY_P_VALUE = 10    # uint16, p-value x 10000
VERIFY_DOF = 11        # uint16, degrees of freedom of the verification test
ARCHIVE_ID = 12        # 12-13: uint32, archive id of the last run
# the run's outcome per joint (bit j-1 = joint j; hostpc.calibrate.outcome)
JOINTS_CALIBRATED = 14       # calibrated from the data and, if pushed, verified
JOINTS_NOT_CALIBRATED = 15   # not determined by the data (unidentifiable, held, prior)
JOINTS_REQUIRED_MISSING = 16  # required (--require-joints) but not calibrated
OUTCOME_FLAGS = 17     # bit0 pushed, bit1 verified, bit2 rolled back, bit3 refused
REASON_CODE = 18       # why the last run did not PASS (Reason below; 0 = it did, or idle)
COMMAND_IGNORED = 19   # the last command the station did NOT take in its state (0: taken)
SERIAL = 20            # 20-35: robot serial number, 32 ASCII characters
SERIAL_LENGTH = 16
MODEL = 40             # 40-55: robot model, 32 ASCII characters
MODEL_LENGTH = 16
JOINTS_PUSHED = 56     # bit j-1 = joint j's offset written to the controller by the run
JOINTS_AS_FOUND = 57   # of JOINTS_CALIBRATED: restored to a cell reference whose recording
                       # run did not measure the zero (it is as it was then)
REASON = 64            # 64-95: the last run's one-line reason, 64 ASCII characters (cut)
REASON_LENGTH = 32

PLC_WRITABLE = frozenset({COMMAND, *range(SERIAL, SERIAL + SERIAL_LENGTH),
                          *range(MODEL, MODEL + MODEL_LENGTH)})


class Command(enum.IntEnum):
    NONE = 0
    START = 1
    ABORT = 2
    ACKNOWLEDGE = 3


class State(enum.IntEnum):
    IDLE = 0
    RUNNING = 1
    PASS = 2
    FAIL = 3
    ERROR = 4


# result codes beyond `hostpc calibrate`'s own exit codes (0-6, 130)
RESULT_NO_SERIAL = 20       # start without a serial number in SERIAL
RESULT_ABORTED = 21         # the PLC aborted the run
RESULT_ARCHIVE_FAILED = 22  # the run finished but could not be archived
RESULT_STATION_ERROR = 23   # the calibration could not be started at all
RESULT_PUSH_PENDING = 24    # start refused: an earlier run's pushed offsets are not verified


class Reason(enum.IntEnum):
    """REASON_CODE: the kind of failure of the last run (the text is in REASON)."""

    NONE = 0                # passed, or nothing to report
    INPUT = 1               # calibrate refused an input: a file or option (exit 2)
    CONTROLLER_UNREACHABLE = 2  # the controller could not be reached / link lost (exit 3)
    CONTROLLER_REFUSED = 3  # the controller refused (estop, busy, limit) (exit 4)
    PUSH_REFUSED = 4        # a guard rail refused the push (exit 5)
    VERIFY_FAILED = 5       # the verification of the pushed offsets failed (exit 6)
    JOINTS_MISSING = 6      # a required joint was not calibrated (exit 7)
    NOT_PUSHED = 7          # the run ended without pushing, or rolled back (exit 0)
    INTERRUPTED = 8         # the run was interrupted (exit 130/143)
    ABORTED = 9             # the PLC aborted the run (result code 21)
    NO_SERIAL = 10          # start without a serial number (result code 20)
    NOT_ARCHIVED = 11       # the run finished but could not be archived (result code 22)
    CANNOT_START = 12       # the calibration could not be started (result code 23)
    INTERNAL = 13           # any other failure of the calibration process
    PUSH_LOST = 14          # the controller lost the run's pushed offsets (exit 4)
    PUSH_PENDING = 15       # start refused: an earlier run's push is not verified (24)
    OFFSETS_CHANGED = 16    # the controller holds neither the run's previous nor its
                            # pushed offsets: no resume continues it (exit 2)


_REASON_BY_CODE = {2: Reason.INPUT, 3: Reason.CONTROLLER_UNREACHABLE,
                   4: Reason.CONTROLLER_REFUSED, 5: Reason.PUSH_REFUSED,
                   6: Reason.VERIFY_FAILED, 7: Reason.JOINTS_MISSING, 130: Reason.INTERRUPTED,
                   143: Reason.INTERRUPTED, 20: Reason.NO_SERIAL, 21: Reason.ABORTED,
                   22: Reason.NOT_ARCHIVED, 23: Reason.CANNOT_START,
                   24: Reason.PUSH_PENDING}
PUSH_LOST_PREFIX = "push lost:"
"""How `hostpc calibrate`'s error line (hostpc.calibrate.resume.PushLost) begins when the
controller no longer has the offsets the run pushed (exit code 4, like a refusal)."""
OFFSETS_CHANGED_PREFIX = "the controller's zero offsets changed since the run"
"""How `hostpc calibrate --resume`'s error line begins (exit code 2, like any input) when
the controller holds offsets that are neither the run's previous nor its pushed ones
(hostpc.calibrate.resume.check_resume_offsets): no resume continues that run."""


def reason_of(state: State, result_code: int, reason: str = "") -> Reason:
    """The REASON_CODE of a finished run in `state` with `result_code` and one-line
    `reason` (a push lost is exit code 4 like a refusal, offsets changed exit code 2 like
    any input: their reasons tell them apart)."""
    if state in (State.IDLE, State.RUNNING, State.PASS):
        return Reason.NONE
    if result_code == 4 and reason.startswith(PUSH_LOST_PREFIX):
        return Reason.PUSH_LOST
    if result_code == 2 and reason.startswith(OFFSETS_CHANGED_PREFIX):
        return Reason.OFFSETS_CHANGED
    if result_code == 0:
        return Reason.NOT_PUSHED
    return _REASON_BY_CODE.get(result_code, Reason.INTERNAL)


def encode_text(text: str, n_registers: int) -> list[int]:
    """ASCII text in `n_registers` registers (2 characters each, NUL-padded, cut to fit)."""
    raw = text.encode("ascii", "replace")[: 2 * n_registers].ljust(2 * n_registers, b"\0")
    return [raw[i] << 8 | raw[i + 1] for i in range(0, len(raw), 2)]


def decode_text(registers: list[int]) -> str:
    """The inverse of encode_text (stops at the first NUL; non-printable bytes dropped)."""
    raw = b"".join(bytes([value >> 8 & 0xFF, value & 0xFF]) for value in registers)
    raw = raw.split(b"\0", 1)[0]
    return "".join(chr(b) for b in raw if 32 <= b < 127).strip()


def encode_int32(value: int) -> list[int]:
    value &= 0xFFFFFFFF
    return [value >> 16, value & 0xFFFF]


def decode_int32(registers: list[int]) -> int:
    value = (registers[0] << 16) | registers[1]
    return value - (1 << 32) if value & 0x80000000 else value


def clamp_uint(value: float, bits: int) -> int:
    return int(min(max(round(value), 0), (1 << bits) - 1))


@dataclass(frozen=True)
class RunOutcome:
    """What the result registers show of a finished run (the joint bitmasks and outcome
    flags: registers 14-17, from the run's outcome block in result.json)."""

    state: State
    result_code: int
    largest_correction_deg: float | None = None
    verify_statistic: float | None = None
    verify_p_value: float | None = None
    verify_dof: int | None = None
    archive_id: int | None = None
    joints_calibrated: int = 0
    joints_not_calibrated: int = 0
    joints_required_missing: int = 0
    outcome_flags: int = 0
    joints_pushed: int = 0
    joints_as_found: int = 0
    reason: str = ""
    """The one-line reason of a run that did not PASS (REASON; its kind: REASON_CODE)."""


FLAG_PUSHED, FLAG_VERIFIED, FLAG_ROLLED_BACK, FLAG_REFUSED = 1, 2, 4, 8


class OutcomeBits(NamedTuple):
    """RunOutcome's joint bitmasks (joint j sets bit j-1) and flags."""

    joints_calibrated: int
    joints_not_calibrated: int
    joints_required_missing: int
    outcome_flags: int
    joints_pushed: int
    joints_as_found: int


def _mask(numbers: Iterable[int]) -> int:
    return sum(1 << (n - 1) for n in numbers if 1 <= n <= 16)


def outcome_bits(outcome: OutcomeFigures | None, push_status: str,
                 pushed_joints: Iterable[int]) -> OutcomeBits:
    """The bitmasks and flags of a run: its outcome (None: a run that wrote no result, e.g.
    stopped during the verification) and what the archive says it pushed (`push_status`,
    the joints whose offsets it wrote: from the result, or the journal of a run without
    one); joints beyond 16 are left out."""
    pushed = _mask(pushed_joints)
    if outcome is None:
        flags = {"pushed": FLAG_PUSHED, "rolled_back": FLAG_ROLLED_BACK}.get(push_status, 0)
        return OutcomeBits(0, 0, 0, flags, pushed, 0)
    flags = ((FLAG_PUSHED if outcome.pushed else 0)
             | (FLAG_VERIFIED if outcome.verified is True else 0)
             | (FLAG_ROLLED_BACK if outcome.verdict == "ROLLED_BACK" else 0)
             | (FLAG_REFUSED if outcome.verdict == "REFUSED" else 0))
    return OutcomeBits(_mask(outcome.calibrated), _mask(outcome.not_calibrated),
                       _mask(outcome.missing_required), flags, pushed,
                       _mask(outcome.as_found))


def outcome_registers(outcome: RunOutcome) -> dict[int, int]:
    """Register address -> value for a finished run's result."""
    values = {STATE: int(outcome.state), RESULT_CODE: clamp_uint(outcome.result_code, 16)}
    correction = outcome.largest_correction_deg
    for address, value in zip(range(LARGEST_CORRECTION, LARGEST_CORRECTION + 2),
                              encode_int32(0 if correction is None else round(correction * 1e4)),
                              strict=True):
        values[address] = value
    statistic = clamp_uint((outcome.verify_statistic or 0.0) * 1000.0, 32)
    values[VERIFY_STATISTIC], values[VERIFY_STATISTIC + 1] = encode_int32(statistic)
    values[VERIFY_P_VALUE] = clamp_uint((outcome.verify_p_value or 0.0) * 1e4, 16)
    values[VERIFY_DOF] = clamp_uint(outcome.verify_dof or 0, 16)
    values[ARCHIVE_ID], values[ARCHIVE_ID + 1] = encode_int32(outcome.archive_id or 0)
    values[JOINTS_CALIBRATED] = outcome.joints_calibrated & 0xFFFF
    values[JOINTS_NOT_CALIBRATED] = outcome.joints_not_calibrated & 0xFFFF
    values[JOINTS_REQUIRED_MISSING] = outcome.joints_required_missing & 0xFFFF
    values[OUTCOME_FLAGS] = outcome.outcome_flags & 0xFFFF
    values[JOINTS_PUSHED] = outcome.joints_pushed & 0xFFFF
    values[JOINTS_AS_FOUND] = outcome.joints_as_found & 0xFFFF
    values[REASON_CODE] = int(reason_of(outcome.state, outcome.result_code, outcome.reason))
    for address, value in enumerate(encode_text(outcome.reason, REASON_LENGTH), start=REASON):
        values[address] = value
    return values
