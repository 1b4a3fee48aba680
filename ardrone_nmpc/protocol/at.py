"""AR.Drone 2.0 AT commands (UDP 5556): records, encoder, sequencer and parser.

docs/protocol.md §2. A command is ASCII ``AT*<NAME>=<seq>[,<arg>]...\\r``; several
commands may share a datagram of at most 1024 bytes, a command never spans two. Arguments are
decimal int32, double-quoted strings, or floats sent as the decimal int32 whose bits are the
IEEE-754 single (``-0.8`` → ``-1085485875``).

Records
-------
A command is an :class:`AtCommand` = sequence number + body. Bodies are frozen dataclasses, one
per command: :class:`Ref`, :class:`Pcmd`, :class:`PcmdMag`, :class:`Ftrim`, :class:`Calib`,
:class:`Config`, :class:`ConfigIds`, :class:`Ctrl`, :class:`Comwdg`, and :class:`UnknownCommand`
for any other well-formed name (``ANIM``, ``LED``, …), which a simulator ignores. Each body
declares its wire ``SIGNATURE`` (``i`` int32, ``f`` float-as-int32, ``s`` quoted string), which
drives both the encoder and the parser. Construction validates that the record is
representable on the wire (int32 ranges, finite float32 values, printable ASCII without ``"``);
float fields are stored rounded to float32, the value the drone receives, so
``parse(encode(c)) == c`` holds exactly. Ranges such as PCMD values in [−1, 1] are *not*
checked here: the command mapping saturates (and flags it); a simulator decides what larger
values do.

Parser
------
:func:`parse_datagram` (strict: the first malformed command raises :class:`AtParseError`) and
:func:`parse_datagram_lenient` (well-formed commands plus the errors, never raises) split on
``\\r``, tolerate a trailing comma (``AT*FTRIM=5,\\r``) and stray ``\\n`` around commands, and
reject datagrams over 1024 bytes and an unterminated last command.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import operator
import re
import struct
from collections.abc import Iterable
from dataclasses import dataclass
from typing import ClassVar, Union

__all__ = [
    "AT_PORT", "AT_TERMINATOR", "AT_MAX_DATAGRAM_BYTES", "AT_SEQ_FIRST", "AT_SEQ_MAX",
    "INT32_MIN", "INT32_MAX", "REF_BASE", "REF_EMERGENCY_BIT", "REF_TAKEOFF_BIT",
    "CTRL_MODE_NONE", "CTRL_MODE_CFG_GET", "CTRL_MODE_ACK", "CTRL_MODE_CUSTOM_CFG_GET",
    "PcmdFlag", "AtParseError", "Ref", "Pcmd", "PcmdMag", "Ftrim", "Calib", "Config",
    "ConfigIds", "Ctrl", "Comwdg", "UnknownCommand", "AtBody", "AtCommand", "AtSequencer",
    "float_to_int32_bits", "int32_bits_to_float", "config_value_text", "pack_commands",
    "parse_command", "parse_datagram", "parse_datagram_lenient",
]

AT_PORT = 5556                   # UDP, client → drone
AT_TERMINATOR = b"\r"            # carriage return; the dev guide's "line feed" is wrong (§2.1)
AT_MAX_DATAGRAM_BYTES = 1024     # ATcodec INTERNAL_BUFFER_SIZE; larger datagrams are rejected
AT_SEQ_FIRST = 1                 # first sequence number; seq 1 also resets the drone's counter
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
AT_SEQ_MAX = INT32_MAX           # the sequencer wraps to AT_SEQ_FIRST after this

# AT*REF bitfield (§2.4): neutral game-pad (bits 18, 20, 22, 24, 28) plus the two buttons.
REF_BASE = 0x11540000            # 290717696: land / idle
REF_EMERGENCY_BIT = 1 << 8       # SELECT: emergency toggle (acted on at its 0→1 edge)
REF_TAKEOFF_BIT = 1 << 9         # START: take-off while 1, land while 0 (a level)

# AT*CTRL modes (ardrone_api.h ARDRONE_CONTROL_MODE).
CTRL_MODE_NONE = 0
CTRL_MODE_CFG_GET = 4            # dump the configuration on TCP 5559
CTRL_MODE_ACK = 5                # clear state bit 6 (config ACK)
CTRL_MODE_CUSTOM_CFG_GET = 6     # dump the custom-configuration id list

_FLOAT32_FORMAT = "<f"           # the IEEE-754 single ...
_INT32_FORMAT = "<i"             # ... and the int32 with the same four bytes


class PcmdFlag(enum.IntFlag):
    """``AT*PCMD`` flag bits (``ARDRONE_PROGRESSIVE_CMD_FLAG``, §2.5)."""

    PROGRESSIVE = 1 << 0         # use the four values; 0 = hover mode (values ignored)
    COMBINED_YAW = 1 << 1        # roll also turns
    ABSOLUTE_CONTROL = 1 << 2    # magnetometer-referenced control (PCMD_MAG)


class AtParseError(ValueError):
    """A malformed AT datagram or command (the only exception the parser raises)."""


def float_to_int32_bits(x: float) -> int:
    """The signed int32 whose bits are the IEEE-754 single of ``x`` (``-0.8`` → ``-1085485875``).

    ``x`` is rounded to float32; NaN and ±inf are encoded too. Raises ValueError (from
    ``OverflowError``) for finite values beyond the float32 range.
    """
    try:
        return struct.unpack(_INT32_FORMAT, struct.pack(_FLOAT32_FORMAT, x))[0]
    except OverflowError as exc:
        raise ValueError(f"{x!r} does not fit a float32") from exc


def int32_bits_to_float(n: int) -> float:
    """The float32 (as a python float) whose bits are the signed int32 ``n``; inverse of
    :func:`float_to_int32_bits`."""
    return struct.unpack(_FLOAT32_FORMAT, struct.pack(_INT32_FORMAT, n))[0]


def config_value_text(value: bool | int | float | str) -> str:
    """The text an ``AT*CONFIG`` value is sent as (§3.1): ``"TRUE"``/``"FALSE"``, decimal ints,
    shortest round-trip decimal floats, strings unchanged."""
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"config value must be finite, got {value!r}")
        return repr(value)
    if isinstance(value, str):
        return value
    raise TypeError(f"unsupported config value type {type(value).__name__}")


# ----------------------------------------------------------------------------- validation

_TEXT_RE = re.compile(r'[ !#-~]*')            # printable ASCII without the double quote
_NAME_RE = re.compile(r'[A-Z][A-Z0-9_]*')
_INT_TOKEN = r'-?[0-9]{1,10}'
_STR_TOKEN = r'"[ !#-~]*"'
_ARG_TOKEN_RE = re.compile(rf'{_INT_TOKEN}|{_STR_TOKEN}')
_COMMAND_RE = re.compile(
    rf'AT\*([A-Z][A-Z0-9_]*)=([0-9]{{1,10}})((?:,(?:{_INT_TOKEN}|{_STR_TOKEN}))*),?')
_ARGS_RE = re.compile(rf',({_INT_TOKEN}|{_STR_TOKEN})')


def _int32(name: str, v) -> int:
    if isinstance(v, bool):
        raise TypeError(f"{name} must be an int, got bool")
    v = operator.index(v)
    if not INT32_MIN <= v <= INT32_MAX:
        raise ValueError(f"{name}={v} outside int32")
    return v


def _float32(name: str, v) -> float:
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v!r}")
    try:
        return struct.unpack(_FLOAT32_FORMAT, struct.pack(_FLOAT32_FORMAT, v))[0]
    except OverflowError as exc:
        raise ValueError(f"{name}={v!r} does not fit a float32") from exc


def _text(name: str, v) -> str:
    if not isinstance(v, str) or not _TEXT_RE.fullmatch(v):
        raise ValueError(f"{name} must be printable ASCII without '\"', got {v!r}")
    return v


_CHECKS = {"i": _int32, "f": _float32, "s": _text}


# ----------------------------------------------------------------------------- command bodies


class _Body:
    """Base of the command bodies: fields in wire order, typed by ``SIGNATURE``."""

    __slots__ = ()
    NAME: ClassVar[str] = ""
    SIGNATURE: ClassVar[str] = ""      # one code per field: i int32, f float32, s string
    MIN_ARGS: ClassVar[int | None] = None  # fewer trailing args accepted (defaults used)

    def __post_init__(self) -> None:
        for f, code in zip(dataclasses.fields(self), self.SIGNATURE):
            object.__setattr__(self, f.name, _CHECKS[code](f.name, getattr(self, f.name)))

    @property
    def at_name(self) -> str:
        """The command name after ``AT*``."""
        return self.NAME

    def wire_args(self) -> tuple[str, ...]:
        """The argument tokens after the sequence number, as sent."""
        out = []
        for f, code in zip(dataclasses.fields(self), self.SIGNATURE):
            v = getattr(self, f.name)
            out.append(str(float_to_int32_bits(v)) if code == "f"
                       else f'"{v}"' if code == "s" else str(v))
        return tuple(out)


@dataclass(frozen=True, slots=True)
class Ref(_Body):
    """``AT*REF``: take-off / land / emergency (§2.4).

    Attributes
    ----------
    bits : the game-pad bitfield (int32). Clients send :data:`REF_BASE` plus the button bits;
        a simulator should look only at bits 8 (:attr:`is_emergency`) and 9 (:attr:`is_takeoff`).
    """

    bits: int = REF_BASE
    NAME: ClassVar[str] = "REF"
    SIGNATURE: ClassVar[str] = "i"

    @classmethod
    def landing(cls) -> Ref:
        """Land / stay landed (290717696)."""
        return cls(REF_BASE)

    @classmethod
    def takeoff(cls) -> Ref:
        """Take off / stay airborne (290718208)."""
        return cls(REF_BASE | REF_TAKEOFF_BIT)

    @classmethod
    def emergency(cls) -> Ref:
        """Emergency button pressed (290717952): cuts the motors, or clears an emergency."""
        return cls(REF_BASE | REF_EMERGENCY_BIT)

    @property
    def is_takeoff(self) -> bool:
        """Bit 9 (START) set."""
        return bool(self.bits & REF_TAKEOFF_BIT)

    @property
    def is_emergency(self) -> bool:
        """Bit 8 (SELECT) set."""
        return bool(self.bits & REF_EMERGENCY_BIT)


@dataclass(frozen=True, slots=True)
class Pcmd(_Body):
    """``AT*PCMD``: progressive command (§2.5).

    Attributes
    ----------
    flags : :class:`PcmdFlag` bits (int32); 0 = hover mode, the values are ignored.
    roll_frac : roll × ``euler_angle_max``; > 0 bank right.
    pitch_frac : pitch × ``euler_angle_max``; < 0 nose down = fly forward.
    gaz_frac : vertical speed × ``control_vz_max``; > 0 climb.
    yaw_frac : yaw rate × ``control_yaw``; > 0 clockwise seen from above.
    """

    flags: int = 0
    roll_frac: float = 0.0
    pitch_frac: float = 0.0
    gaz_frac: float = 0.0
    yaw_frac: float = 0.0
    NAME: ClassVar[str] = "PCMD"
    SIGNATURE: ClassVar[str] = "iffff"

    @classmethod
    def hover(cls) -> Pcmd:
        """Hover mode: ``AT*PCMD=seq,0,0,0,0,0`` (position hold on the bottom camera)."""
        return cls()

    @classmethod
    def move(cls, roll_frac: float, pitch_frac: float, gaz_frac: float, yaw_frac: float, *,
             combined_yaw: bool = False) -> Pcmd:
        """A progressive command (flag bit 0 set) with the four values."""
        flags = PcmdFlag.PROGRESSIVE | (PcmdFlag.COMBINED_YAW if combined_yaw else 0)
        return cls(int(flags), roll_frac, pitch_frac, gaz_frac, yaw_frac)


@dataclass(frozen=True, slots=True)
class PcmdMag(_Body):
    """``AT*PCMD_MAG``: :class:`Pcmd` plus the controller's compass heading (§2.3).

    ``psi_frac`` and ``psi_accuracy_frac`` are presumably normalised to [−1, 1] (0 = north);
    their scaling is not confirmed (§7).
    """

    flags: int = 0
    roll_frac: float = 0.0
    pitch_frac: float = 0.0
    gaz_frac: float = 0.0
    yaw_frac: float = 0.0
    psi_frac: float = 0.0
    psi_accuracy_frac: float = 0.0
    NAME: ClassVar[str] = "PCMD_MAG"
    SIGNATURE: ClassVar[str] = "iffffff"


@dataclass(frozen=True, slots=True)
class Ftrim(_Body):
    """``AT*FTRIM``: flat trim (only when landed on level ground)."""

    NAME: ClassVar[str] = "FTRIM"


@dataclass(frozen=True, slots=True)
class Calib(_Body):
    """``AT*CALIB``: calibrate ``device`` (0 = magnetometer; only while flying)."""

    device: int = 0
    NAME: ClassVar[str] = "CALIB"
    SIGNATURE: ClassVar[str] = "i"


@dataclass(frozen=True, slots=True)
class Config(_Body):
    """``AT*CONFIG``: set one configuration key, e.g. ``("control:altitude_max", "3000")``."""

    key: str
    value: str
    NAME: ClassVar[str] = "CONFIG"
    SIGNATURE: ClassVar[str] = "ss"

    @classmethod
    def of(cls, key: str, value: bool | int | float | str) -> Config:
        """``key`` set to ``value`` formatted by :func:`config_value_text`."""
        return cls(key, config_value_text(value))


@dataclass(frozen=True, slots=True)
class ConfigIds(_Body):
    """``AT*CONFIG_IDS``: the multiconfig ids (8 hex chars each) preceding an ``AT*CONFIG``."""

    session_id: str
    profile_id: str
    application_id: str
    NAME: ClassVar[str] = "CONFIG_IDS"
    SIGNATURE: ClassVar[str] = "sss"


@dataclass(frozen=True, slots=True)
class Ctrl(_Body):
    """``AT*CTRL``: control-port mode (``CTRL_MODE_*``). Sent as ``mode,0``; the parser also
    accepts the one-argument form ``AT*CTRL=seq,mode`` (cvdrone, dev guide)."""

    mode: int = CTRL_MODE_NONE
    arg: int = 0
    NAME: ClassVar[str] = "CTRL"
    SIGNATURE: ClassVar[str] = "ii"
    MIN_ARGS: ClassVar[int | None] = 1


@dataclass(frozen=True, slots=True)
class Comwdg(_Body):
    """``AT*COMWDG``: reset the communication watchdog (state bit 30)."""

    NAME: ClassVar[str] = "COMWDG"


@dataclass(frozen=True, slots=True)
class UnknownCommand(_Body):
    """A well-formed command of any other name (``ANIM``, ``LED``, …), arguments kept as their
    wire tokens (``"-12"``, ``'"text"'``)."""

    name: str
    args: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME_RE.fullmatch(self.name):
            raise ValueError(f"invalid command name {self.name!r}")
        if self.name in _BODIES:
            raise ValueError(f"{self.name} is a known command; use its record")
        args = tuple(self.args)
        for a in args:
            if not isinstance(a, str) or not _ARG_TOKEN_RE.fullmatch(a):
                raise ValueError(f"invalid argument token {a!r}")
        object.__setattr__(self, "args", args)

    @property
    def at_name(self) -> str:
        return self.name

    def wire_args(self) -> tuple[str, ...]:
        return self.args


AtBody = Union[Ref, Pcmd, PcmdMag, Ftrim, Calib, Config, ConfigIds, Ctrl, Comwdg, UnknownCommand]
_BODIES: dict[str, type[_Body]] = {
    c.NAME: c for c in (Ref, Pcmd, PcmdMag, Ftrim, Calib, Config, ConfigIds, Ctrl, Comwdg)}


@dataclass(frozen=True, slots=True)
class AtCommand:
    """One numbered command.

    Attributes
    ----------
    seq : sequence number, 0 … 2³¹−1 (clients start at 1; the drone executes a command only if
        its seq exceeds the last accepted one, and seq 1 resets that counter).
    body : the command record.
    """

    seq: int
    body: AtBody

    def __post_init__(self) -> None:
        seq = _int32("seq", self.seq)
        if seq < 0:
            raise ValueError(f"seq must be >= 0, got {seq}")
        if not isinstance(self.body, _Body):
            raise TypeError(f"body must be a command record, got {type(self.body).__name__}")
        object.__setattr__(self, "seq", seq)

    def encode(self) -> bytes:
        """``AT*NAME=seq,args...\\r`` as ASCII bytes."""
        head = f"AT*{self.body.at_name}={self.seq}"
        return (",".join((head, *self.body.wire_args())) + "\r").encode("ascii")


def pack_commands(commands: Iterable[AtCommand],
                  max_datagram_bytes: int = AT_MAX_DATAGRAM_BYTES) -> list[bytes]:
    """Concatenate encoded commands, in order, into as few datagrams of at most
    ``max_datagram_bytes`` as greedy packing gives; a command is never split.

    Raises ValueError if one command alone exceeds the limit.
    """
    if not 0 < max_datagram_bytes <= AT_MAX_DATAGRAM_BYTES:
        raise ValueError(f"max_datagram_bytes must be in 1..{AT_MAX_DATAGRAM_BYTES}")
    datagrams: list[bytes] = []
    current = bytearray()
    for cmd in commands:
        raw = cmd.encode()
        if len(raw) > max_datagram_bytes:
            raise ValueError(f"AT*{cmd.body.at_name} is {len(raw)} bytes encoded, "
                             f"over the {max_datagram_bytes}-byte datagram limit")
        if len(current) + len(raw) > max_datagram_bytes:
            datagrams.append(bytes(current))
            current.clear()
        current += raw
    if current:
        datagrams.append(bytes(current))
    return datagrams


class AtSequencer:
    """Numbers commands from 1 and packs them into datagrams (one per sender; not thread-safe).

    After :data:`AT_SEQ_MAX` the numbering wraps to 1, which the drone takes as a reset.

    Parameters
    ----------
    max_datagram_bytes : datagram size limit (≤ 1024).
    """

    def __init__(self, max_datagram_bytes: int = AT_MAX_DATAGRAM_BYTES) -> None:
        if not 0 < max_datagram_bytes <= AT_MAX_DATAGRAM_BYTES:
            raise ValueError(f"max_datagram_bytes must be in 1..{AT_MAX_DATAGRAM_BYTES}")
        self.max_datagram_bytes = max_datagram_bytes
        self._next = AT_SEQ_FIRST

    @property
    def next_seq(self) -> int:
        """The sequence number the next command gets."""
        return self._next

    def reset(self, next_seq: int = AT_SEQ_FIRST) -> None:
        """Restart the numbering (after a client restart or a link loss)."""
        if not AT_SEQ_FIRST <= next_seq <= AT_SEQ_MAX:
            raise ValueError(f"next_seq must be in {AT_SEQ_FIRST}..{AT_SEQ_MAX}")
        self._next = next_seq

    @staticmethod
    def _after(seq: int) -> int:
        return AT_SEQ_FIRST if seq >= AT_SEQ_MAX else seq + 1

    def number(self, body: AtBody) -> AtCommand:
        """``body`` with the next sequence number."""
        cmd = AtCommand(self._next, body)
        self._next = self._after(self._next)
        return cmd

    def pack(self, bodies: Iterable[AtBody]) -> list[bytes]:
        """Number ``bodies`` consecutively and pack them into datagrams (see
        :func:`pack_commands`). On error no sequence number is consumed."""
        seq, cmds = self._next, []
        for body in bodies:
            cmds.append(AtCommand(seq, body))
            seq = self._after(seq)
        datagrams = pack_commands(cmds, self.max_datagram_bytes)
        self._next = seq
        return datagrams


# ----------------------------------------------------------------------------- parser


def _short(raw: bytes) -> str:
    return repr(raw if len(raw) <= 48 else raw[:48] + b"...")


def parse_command(raw: bytes) -> AtCommand:
    """Parse one command without its ``\\r`` (stray ``\\n`` around it are ignored).

    Raises :class:`AtParseError` for anything that is not a well-formed command: bad syntax,
    non-ASCII bytes, out-of-range numbers, wrong argument count or types for a known command,
    non-finite floats.
    """
    raw = bytes(raw).strip(b"\n")
    if not raw.isascii():
        raise AtParseError(f"non-ASCII bytes in command {_short(raw)}")
    m = _COMMAND_RE.fullmatch(raw.decode("ascii"))
    if m is None:
        raise AtParseError(f"malformed command {_short(raw)}")
    name, seq_text, args_text = m.groups()
    tokens = _ARGS_RE.findall(args_text)
    try:
        cls = _BODIES.get(name)
        if cls is None:
            body: _Body = UnknownCommand(name, tuple(tokens))
        else:
            sig = cls.SIGNATURE
            min_args = len(sig) if cls.MIN_ARGS is None else cls.MIN_ARGS
            if not min_args <= len(tokens) <= len(sig):
                raise AtParseError(f"AT*{name} takes {len(sig)} arguments, got {len(tokens)}")
            values = []
            for tok, code in zip(tokens, sig):
                if (code == "s") != tok.startswith('"'):
                    raise AtParseError(f"AT*{name}: argument {tok!r} has the wrong type")
                if code == "s":
                    values.append(tok[1:-1])
                else:
                    n = int(tok)
                    if not INT32_MIN <= n <= INT32_MAX:
                        raise AtParseError(f"AT*{name}: {tok} outside int32")
                    values.append(int32_bits_to_float(n) if code == "f" else n)
            body = cls(*values)
        return AtCommand(int(seq_text), body)
    except AtParseError:
        raise
    except (ValueError, TypeError) as exc:     # record validation: range, non-finite float
        raise AtParseError(f"invalid command {_short(raw)}: {exc}") from exc


def _chunks(data: bytes) -> tuple[list[bytes], AtParseError | None]:
    data = bytes(data)
    if len(data) > AT_MAX_DATAGRAM_BYTES:
        return [], AtParseError(f"datagram of {len(data)} bytes exceeds "
                                f"{AT_MAX_DATAGRAM_BYTES}")
    *chunks, tail = data.split(AT_TERMINATOR)
    err = None
    if tail.strip(b"\n"):
        err = AtParseError(f"unterminated command {_short(tail)}")
    return [c for c in chunks if c.strip(b"\n")], err


def parse_datagram(data: bytes) -> list[AtCommand]:
    """Parse a whole datagram; the first malformed part raises :class:`AtParseError`.

    Empty chunks (``\\r\\r``) and stray ``\\n`` are skipped; an empty datagram gives ``[]``.
    """
    chunks, err = _chunks(data)
    commands = [parse_command(c) for c in chunks]
    if err is not None:
        raise err
    return commands


def parse_datagram_lenient(data: bytes) -> tuple[list[AtCommand], list[AtParseError]]:
    """Parse what can be parsed: the well-formed commands in order, and one error per malformed
    command (the drone ignores those, §5 rule 2). Never raises for ``bytes`` input; a datagram
    over 1024 bytes gives no commands and one error."""
    chunks, tail_err = _chunks(data)
    commands: list[AtCommand] = []
    errors: list[AtParseError] = []
    for c in chunks:
        try:
            commands.append(parse_command(c))
        except AtParseError as exc:
            errors.append(exc)
    if tail_err is not None:
        errors.append(tail_err)
    return commands, errors
