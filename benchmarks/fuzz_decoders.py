"""Fuzz the wire decoders: every malformed input must raise the module's own error type.

    python benchmarks/fuzz_decoders.py                       # 100 000 inputs per target
    python benchmarks/fuzz_decoders.py --inputs 20000 --targets navdata,mocap
    python benchmarks/fuzz_decoders.py --atheris             # coverage-guided (pip install .[fuzz])

Targets (the code that meets bytes from the network):

``navdata``  :func:`~ardrone_nmpc.protocol.navdata.decode_navdata`, then the link's conversion
             :func:`~ardrone_nmpc.links.drone_link.navdata_sample_of`; allowed: NavdataError.
``mocap``    :func:`~ardrone_nmpc.protocol.mocap.decode_mocap`, then
             :func:`~ardrone_nmpc.links.mocap_link.mocap_pose_of` per pose; allowed: MocapError.
``at``       :func:`~ardrone_nmpc.protocol.at.parse_datagram` (allowed: AtParseError) and
             ``parse_datagram_lenient`` (never raises), which must agree; every parsed command
             must re-encode to itself.
``at-sim``   the simulated drone's AT receiver,
             :meth:`~ardrone_nmpc.sim.drone_server.DroneServer.handle_at_datagram`, on a running
             server (physics and navdata threads on 127.0.0.1): nothing may raise, and the
             server threads must be alive and still stream navdata at the end.

Inputs come from a structure-aware random generator (valid packets with random fields, NaN,
±inf and extreme values, random option/item layouts) and a mutator (bit flips, interesting
u16/u32 values over size and count fields, truncation, insertion, splicing); half of the
mutated navdata packets get their checksum repaired so the mutations reach the option walk.
An *unexpected* exception is anything but the allowed error type (or an inconsistency); each
is printed with the input's hex, and the exit status is 1 if any occurred.

``--atheris`` runs atheris (libFuzzer, coverage-guided) on navdata, mocap and at instead, one
child process per target with ``-runs=--atheris-runs``, seeded with the generator's packets.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import re
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

if __name__ == "__main__" and sys.argv[1:2] == ["--atheris-child"]:
    # An atheris child instruments the project's code as it is imported, before anything else
    # imports it (instrument_all() after the fact would also instrument numpy: minutes).
    import atheris

    with atheris.instrument_imports(include=["ardrone_nmpc"]):
        import ardrone_nmpc.links.drone_link  # noqa: F401
        import ardrone_nmpc.links.mocap_link  # noqa: F401 - and the protocol modules they use

from ardrone_nmpc.links.drone_link import navdata_sample_of
from ardrone_nmpc.links.mocap_link import mocap_pose_of
from ardrone_nmpc.protocol import at as at_mod
from ardrone_nmpc.protocol import mocap as mocap_mod
from ardrone_nmpc.protocol import navdata as nav_mod

# ----------------------------------------------------------------------------- values

_SPECIAL_F64 = (0.0, -0.0, 1.0, -1.0, math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324,
                3.4028235e38, 1e39, 2.0**31, -(2.0**31))
_INTERESTING_U16 = (0, 1, 2, 3, 4, 5, 7, 8, 9, 72, 75, 148, 152, 328, 0x7FFF, 0x8000, 0xFFFE,
                    0xFFFF)
_INTERESTING_U32 = (0, 1, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 0x55667788, 0x55667789,
                    0x55667787, 0x10000, 0xFFFF)


def _float(rng: random.Random) -> float:
    r = rng.random()
    if r < 0.25:
        return rng.choice(_SPECIAL_F64)
    if r < 0.35:
        return struct.unpack("<d", rng.randbytes(8))[0]   # any bit pattern, NaN payloads too
    return rng.uniform(-5000.0, 5000.0)


def _float32_bits(rng: random.Random) -> bytes:
    if rng.random() < 0.3:
        return rng.randbytes(4)                            # NaN/inf/subnormal patterns
    x = _float(rng)
    try:
        return struct.pack("<f", x)
    except OverflowError:
        return struct.pack("<f", math.copysign(math.inf, x))


# ----------------------------------------------------------------------------- generators


def _navdata_demo_payload(rng: random.Random) -> bytes:
    """The 144 bytes after the demo option's head, every float drawn hostile."""
    ints = struct.pack("<II", rng.getrandbits(32), rng.choice((0, 50, 100, 255, 2**32 - 1)))
    floats = b"".join(_float32_bits(rng) for _ in range(3))
    alt = struct.pack("<i", rng.choice((0, 1234, -1, 2**31 - 1, -(2**31))))
    vel = b"".join(_float32_bits(rng) for _ in range(3))
    rest = struct.pack("<I", rng.getrandbits(32))
    rest += b"".join(_float32_bits(rng) for _ in range(12))
    rest += struct.pack("<II", rng.getrandbits(32), rng.getrandbits(32))
    rest += b"".join(_float32_bits(rng) for _ in range(12))
    return ints + floats + alt + vel + rest


def gen_navdata(rng: random.Random) -> bytes:
    """A navdata packet: valid layout, random fields; sometimes a structural fault."""
    magic = rng.choice((nav_mod.NAVDATA_MAGIC, nav_mod.NAVDATA_MAGIC_ALT))
    body = bytearray(struct.pack("<IIIi", magic, rng.getrandbits(32), rng.getrandbits(32),
                                 rng.getrandbits(32) - 2**31))
    for _ in range(rng.choice((0, 1, 1, 2, 3, 6))):
        tag = rng.choice((0, 0, 1, 16, 26, rng.getrandbits(16)))
        payload = (_navdata_demo_payload(rng) + rng.randbytes(rng.choice((0, 0, 4, 20))) if tag == 0
                   else rng.randbytes(rng.choice((0, 4, 8, 324, rng.randrange(64)))))
        size = len(payload) + 4
        if rng.random() < 0.1:                             # a lying size field
            size = rng.choice(_INTERESTING_U16)
        body += struct.pack("<HH", tag, size) + payload
    cks = sum(body) & 0xFFFFFFFF
    if rng.random() < 0.05:
        cks ^= 1 << rng.randrange(32)
    size = 8 if rng.random() > 0.05 else rng.choice(_INTERESTING_U16)
    out = bytes(body) + struct.pack("<HHI", 0xFFFF, size, cks)
    if rng.random() < 0.1:
        out += rng.randbytes(rng.randrange(1, 16))         # ignored trailing bytes
    return out


def _mocap_name(rng: random.Random) -> bytes:
    r = rng.random()
    if r < 0.6:
        return rng.choice((b"ardrone", b"wand", b"obj", b"x" * 24, b""))
    if r < 0.8:
        return bytes(rng.randrange(0x80, 0x100) for _ in range(rng.randrange(1, 25)))
    return rng.randbytes(24)                               # NULs anywhere, any bytes


def gen_mocap(rng: random.Random) -> bytes:
    """A mocap datagram: pose items and unknown items, counts and sizes sometimes lying."""
    items = []
    for _ in range(rng.choice((0, 1, 1, 2, 3, 13, 14))):
        if rng.random() < 0.85:
            data = struct.pack("<24s6d", _mocap_name(rng), *(_float(rng) for _ in range(6)))
            data += rng.randbytes(rng.choice((0, 0, 0, 5)))
            item_id = 0
        else:
            item_id, data = rng.randrange(1, 256), rng.randbytes(rng.randrange(40))
        size = len(data) if rng.random() > 0.1 else rng.choice(_INTERESTING_U16)
        items.append(struct.pack("<BH", item_id, size) + data)
    count = len(items) if rng.random() > 0.1 else rng.randrange(256)
    out = struct.pack("<IB", rng.getrandbits(32), count) + b"".join(items)
    pad = rng.choice((0, 256, 512, 1024))
    return out + bytes(max(0, pad - len(out)))


_AT_NAMES = ("REF", "PCMD", "PCMD_MAG", "FTRIM", "CALIB", "CONFIG", "CONFIG_IDS", "CTRL",
             "COMWDG", "ANIM", "LED", "X", "ref", "P CMD", "")
_AT_CONFIG_KEYS = ("general:navdata_demo", "general:navdata_options", "control:altitude_max",
                   "control:euler_angle_max", "control:control_vz_max", "control:control_yaw",
                   "custom:session_id")
_AT_VALUES = ("TRUE", "FALSE", "1e300", "-1e300", "nan", "inf", "0", "-1", "3000", "0.52",
              "99999999999999999999999", "", "abc")


def _at_token(rng: random.Random) -> str:
    r = rng.random()
    if r < 0.35:
        return str(rng.choice((0, 1, -1, 4, 5, 6, 290718208, 290717696, 290717952, 1065353216,
                               -1085485875, 2**31 - 1, -(2**31), 2139095040, 2143289344,
                               rng.getrandbits(31))))
    if r < 0.42:
        return str(rng.choice((2**31, -(2**31) - 1, 10**10, 10**11, -(10**10))))
    if r < 0.9:
        return '"' + rng.choice(_AT_CONFIG_KEYS + _AT_VALUES) + '"'
    return rng.choice(('1.5', '"unterminated', '"a"b"', '"\x7f"', '"é"', "", " 1", "0x10",
                       "+1", "--1", "1e5", "nan", '""', ",", "\t"))


def gen_at_command(rng: random.Random) -> bytes:
    """One command, ``\\r``-terminated or not: mostly well-formed, with hostile arguments."""
    if rng.random() < 0.3:
        key, value = rng.choice(_AT_CONFIG_KEYS), rng.choice(_AT_VALUES)
        text = f'AT*CONFIG={rng.randrange(1, 1000)},"{key}","{value}"'
    else:
        name = rng.choice(_AT_NAMES)
        seq = rng.choice((str(rng.randrange(0, 1000)), "1", "0", "-1", "2147483648",
                          "99999999999", "", "x"))
        args = [_at_token(rng) for _ in range(rng.choice((0, 1, 2, 4, 5, 7, 8)))]
        text = ",".join([f"AT*{name}={seq}", *args]) + ("," if rng.random() < 0.05 else "")
    raw = text.encode("utf-8")
    return raw + rng.choice((b"\r", b"\r", b"\r", b"\r\n", b"\n", b""))


def gen_at(rng: random.Random) -> bytes:
    """A datagram of several commands; sometimes over the 1024-byte limit."""
    return b"".join(gen_at_command(rng) for _ in range(rng.choice((1, 1, 1, 2, 3, 8, 30))))


# ----------------------------------------------------------------------------- mutation


def mutate(rng: random.Random, data: bytes, corpus: list[bytes]) -> bytes:
    """One to four random byte-level mutations of ``data``."""
    buf = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(9)
        n = len(buf)
        if op == 0 and n:                                  # flip a bit
            buf[rng.randrange(n)] ^= 1 << rng.randrange(8)
        elif op == 1 and n:                                # an interesting byte
            buf[rng.randrange(n)] = rng.choice((0, 1, 0x0D, 0x0A, 0x22, 0x2C, 0x7F, 0x80,
                                                0xFF))
        elif op == 2 and n >= 2:                           # an interesting u16 (sizes)
            i = rng.randrange(n - 1)
            buf[i:i + 2] = struct.pack("<H", rng.choice(_INTERESTING_U16 + (n, n - i)))
        elif op == 3 and n >= 4:                           # an interesting u32
            i = rng.randrange(n - 3)
            buf[i:i + 4] = struct.pack("<I", rng.choice(_INTERESTING_U32))
        elif op == 4 and n:                                # truncate
            del buf[rng.randrange(n):]
        elif op == 5 and n:                                # delete a range
            i = rng.randrange(n)
            del buf[i:i + rng.randint(1, 16)]
        elif op == 6:                                      # insert random bytes
            i = rng.randint(0, n)
            buf[i:i] = rng.randbytes(rng.randint(1, 8))
        elif op == 7 and n:                                # duplicate a range
            i = rng.randrange(n)
            buf[i:i] = buf[i:i + rng.randint(1, 32)]
        elif op == 8 and corpus:                           # splice with another input
            other = rng.choice(corpus)
            cut = rng.randint(0, n)
            buf = buf[:cut] + other[rng.randint(0, len(other)):]
    return bytes(buf)


def repair_navdata_checksum(data: bytes) -> bytes:
    """Walk the options like the decoder and rewrite the checksum value of a well-placed
    checksum option, so that mutations of the options themselves are decoded further."""
    buf = bytearray(data)
    off, n = nav_mod.HEADER_BYTES, len(buf)
    while off + 4 <= n:
        tag, size = struct.unpack_from("<HH", buf, off)
        if size < 4 or off + size > n:
            break
        if tag == 0xFFFF:
            if size == 8:
                struct.pack_into("<I", buf, off + 4, sum(buf[:off]) & 0xFFFFFFFF)
            break
        off += size
    return bytes(buf)


def at_text_mutate(rng: random.Random, data: bytes) -> bytes:
    """Replace one syntax character of an AT datagram by another (keeps it mostly ASCII)."""
    specials = [i for i, b in enumerate(data) if b in b'=,"*\r']
    if not specials:
        return data
    i = rng.choice(specials)
    swap = rng.choice((b"", b",", b'"', b"\r", b"=", b",,", b"\n", b"\x00"))
    return data[:i] + swap + data[i + 1:]


# ----------------------------------------------------------------------------- targets


class Inconsistent(AssertionError):
    """The decoder returned something that breaks its own contract."""


def check_navdata(data: bytes) -> bool:
    packet = nav_mod.decode_navdata(data)
    navdata_sample_of(packet, 0.0)
    return True


def check_mocap(data: bytes) -> bool:
    frame = mocap_mod.decode_mocap(data)
    for pose in frame.poses.values():
        mocap_pose_of(pose, 0.0)
    return True


def check_at(data: bytes) -> bool:
    commands, errors = at_mod.parse_datagram_lenient(data)
    if not all(isinstance(e, at_mod.AtParseError) for e in errors):
        raise Inconsistent(f"lenient parser returned a non-AtParseError: {errors!r}")
    for cmd in commands:
        if at_mod.parse_command(cmd.encode()[:-1]) != cmd:
            raise Inconsistent(f"{cmd!r} does not re-encode to itself")
    try:
        strict = at_mod.parse_datagram(data)
    except at_mod.AtParseError:
        if not errors:
            raise Inconsistent("strict parser rejects what the lenient one accepts") from None
        raise
    if errors or strict != commands:
        raise Inconsistent("strict and lenient parsers disagree")
    return True


@dataclass
class Target:
    """A decoder under test: its check, allowed error, generator and seed mutator."""

    name: str
    check: Callable[[bytes], bool]
    allowed: type[Exception] | tuple[type[Exception], ...]
    generate: Callable[[random.Random], bytes]
    post_mutate: Callable[[random.Random, bytes], bytes] | None = None


def _navdata_post(rng: random.Random, data: bytes) -> bytes:
    return repair_navdata_checksum(data) if rng.random() < 0.5 else data


def _at_post(rng: random.Random, data: bytes) -> bytes:
    return at_text_mutate(rng, data) if rng.random() < 0.3 else data


TARGETS = {
    "navdata": Target("navdata", check_navdata, nav_mod.NavdataError, gen_navdata, _navdata_post),
    "mocap": Target("mocap", check_mocap, mocap_mod.MocapError, gen_mocap),
    "at": Target("at", check_at, at_mod.AtParseError, gen_at, _at_post),
}


# ----------------------------------------------------------------------------- the run


@dataclass
class Result:
    """Counts of one target's run."""

    name: str
    inputs: int = 0
    accepted: int = 0
    rejected: int = 0
    unexpected: int = 0
    elapsed_s: float = 0.0
    slowest_us: float = 0.0
    slowest_input: bytes = b""
    error_kinds: Counter = field(default_factory=Counter)
    failures: list[tuple[bytes, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


_NUMBERS = re.compile(r"0x[0-9a-f]+|\d+")


def _kind(exc: Exception) -> str:
    """The error message up to its first quoted value, numbers blanked: roughly one 'kind'
    per code path that rejected the input."""
    text = re.split(r"[\"'(]", str(exc), maxsplit=1)[0]
    return _NUMBERS.sub("#", text).strip()[:70]


def inputs_of(target: Target, n: int, seed: int):
    """``n`` inputs: a third freshly generated, the rest mutated from a rolling corpus."""
    rng = random.Random(seed)
    corpus = [target.generate(rng) for _ in range(64)]
    for i in range(n):
        if rng.random() < 0.33:
            data = target.generate(rng)
            corpus[rng.randrange(len(corpus))] = data
        else:
            data = mutate(rng, rng.choice(corpus), corpus)
            if target.post_mutate is not None:
                data = target.post_mutate(rng, data)
        yield data


def run_target(target: Target, n: int, seed: int, feed: Callable[[bytes], object] | None = None
               ) -> Result:
    """Feed ``n`` inputs to ``target.check`` (or ``feed``) and count the outcomes."""
    res = Result(target.name)
    call = feed or target.check
    allowed = () if feed is not None else target.allowed
    t0 = time.perf_counter()
    for data in inputs_of(target, n, seed):
        t = time.perf_counter()
        try:
            call(data)
            res.accepted += 1
        except allowed as exc:
            res.rejected += 1
            res.error_kinds[_kind(exc)] += 1
        except Exception as exc:  # noqa: BLE001 - counting them is the point
            res.unexpected += 1
            if len(res.failures) < 20:
                res.failures.append((data, f"{type(exc).__name__}: {exc}"))
        took_us = (time.perf_counter() - t) * 1e6
        if took_us > res.slowest_us:
            res.slowest_us, res.slowest_input = took_us, data
        res.inputs += 1
    res.elapsed_s = time.perf_counter() - t0
    return res


def run_at_sim(n: int, seed: int) -> Result:
    """The simulator's AT receiver on a running server; afterwards its threads must be alive
    and navdata must still arrive (on 127.0.0.1) and decode."""
    from ardrone_nmpc.config.schema import ExperimentConfig
    from ardrone_nmpc.protocol.navdata import NAVDATA_WAKEUP, decode_navdata
    from ardrone_nmpc.sim.drone_server import DroneServer
    from ardrone_nmpc.sim.plant import AirframePlant

    cfg = ExperimentConfig()
    server = DroneServer(AirframePlant.from_config(cfg.sim, cfg.drone), navdata_timeout_s=None)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(1.0)
    try:
        server.start()
        client.sendto(NAVDATA_WAKEUP, ("127.0.0.1", server.navdata_port))
        server.handle_at_datagram(b'AT*CONFIG=1,"general:navdata_demo","TRUE"\r'
                                  b"AT*REF=2,290718208\r")
        # the plant's first airborne steps compile its kernels (≈ 1 s, under the server lock):
        # not a stall of the receiver, so wait for them before timing anything
        deadline = time.monotonic() + 60.0
        while server.counters.physics_steps < 100 and time.monotonic() < deadline:
            time.sleep(0.05)
        res = run_target(TARGETS["at"], n, seed, feed=server.handle_at_datagram)
        res.name = "at-sim"
        alive = sorted(t.name for t in threading.enumerate()
                       if t.name.startswith("drone-server-") and t.is_alive())
        if len(alive) < 3:
            res.unexpected += 1
            res.notes.append(f"server threads alive afterwards: {alive}")
        while True:                                    # drain what queued up meanwhile
            client.setblocking(False)
            try:
                client.recv(4096)
            except BlockingIOError:
                break
        client.settimeout(1.0)
        client.sendto(NAVDATA_WAKEUP, ("127.0.0.1", server.navdata_port))
        try:
            decode_navdata(client.recv(4096))
        except (OSError, ValueError) as exc:
            res.unexpected += 1
            res.notes.append(f"no decodable navdata after the fuzzing: {exc}")
        c = server.counters
        res.notes.append(f"{c.at_commands_applied} commands applied, {c.malformed_datagrams} "
                         f"malformed datagrams, plant mode {server.plant.mode.value}")
        return res
    finally:
        client.close()
        server.stop()


# ----------------------------------------------------------------------------- atheris


def _atheris_child(name: str, libfuzzer_args: list[str]) -> None:
    """Run atheris on one target (never returns: libFuzzer exits the process)."""
    import atheris

    target = TARGETS[name]
    allowed = target.allowed

    def one_input(data: bytes) -> None:
        try:
            target.check(data)
        except allowed:
            pass

    atheris.Setup([sys.argv[0], *libfuzzer_args], one_input)
    atheris.Fuzz()


def run_atheris(names: list[str], runs: int, seed: int) -> int:
    """One atheris child per target; returns the number of targets that crashed."""
    try:
        import atheris  # noqa: F401
    except ImportError:
        print("atheris is not installed (pip install -e .[fuzz]); nothing run", file=sys.stderr)
        return 1
    crashed = 0
    print(f"{'target':<8} {'runs':>9} {'cov':>6} {'ft':>6} {'corpus':>7} {'time_s':>7} "
          f"{'inputs/s':>9}  result")
    for name in names:
        if name not in TARGETS:
            print(f"{name:<8} (atheris: skipped, not a pure decoder)")
            continue
        with tempfile.TemporaryDirectory(prefix=f"fuzz-{name}-") as corpus:
            rng = random.Random(seed)
            for i in range(256):                       # seeds: the structured generator
                Path(corpus, f"seed{i}").write_bytes(TARGETS[name].generate(rng))
            args = [sys.executable, __file__, "--atheris-child", name, "--",
                    f"-runs={runs}", f"-seed={seed + 1}", "-max_len=4200",
                    "-print_final_stats=1", corpus]
            t0 = time.perf_counter()
            proc = subprocess.run(args, capture_output=True, text=True)
            elapsed = time.perf_counter() - t0
        log = proc.stderr
        done = re.findall(r"#(\d+)\s+DONE\s+cov: (\d+) ft: (\d+) corp: (\d+)", log)
        if proc.returncode == 0 and done:
            n, cov, ft, corp = done[-1]
            print(f"{name:<8} {int(n):>9} {cov:>6} {ft:>6} {corp:>7} {elapsed:>7.1f} "
                  f"{int(n) / elapsed:>9.0f}  no crash")
        else:
            crashed += 1
            tail = "\n".join(log.strip().splitlines()[-25:])
            print(f"{name:<8} crashed or failed (exit {proc.returncode}) after {elapsed:.1f} s:"
                  f"\n{tail}")
    return crashed


# ----------------------------------------------------------------------------- main


def _report(results: list[Result], save_dir: Path | None, kinds: bool) -> int:
    print(f"{'target':<8} {'inputs':>8} {'accepted':>9} {'rejected':>9} {'unexpected':>10} "
          f"{'kinds':>6} {'time_s':>7} {'inputs/s':>9} {'slowest_us':>10}")
    bad = 0
    for r in results:
        print(f"{r.name:<8} {r.inputs:>8} {r.accepted:>9} {r.rejected:>9} {r.unexpected:>10} "
              f"{len(r.error_kinds):>6} {r.elapsed_s:>7.1f} {r.inputs / r.elapsed_s:>9.0f} "
              f"{r.slowest_us:>10.0f}")
        bad += r.unexpected
    for r in results:
        if kinds:
            print(f"  {r.name} slowest input ({r.slowest_us:.0f} us): {r.slowest_input[:120]!r}")
            for kind, count in r.error_kinds.most_common():
                print(f"  {r.name} rejected {count:>7}: {kind}")
        for note in r.notes:
            print(f"  {r.name}: {note}")
        for i, (data, what) in enumerate(r.failures):
            print(f"  {r.name} UNEXPECTED {what}\n    input: {data.hex()}")
            if save_dir is not None:
                save_dir.mkdir(parents=True, exist_ok=True)
                (save_dir / f"{r.name}-{i}.bin").write_bytes(data)
    return 1 if bad else 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--atheris-child"]:
        _atheris_child(argv[1], argv[3:] if argv[2:3] == ["--"] else argv[2:])
        return 0
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--inputs", type=int, default=100_000, help="inputs per target")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--targets", default="navdata,mocap,at,at-sim",
                   help="comma-separated: navdata, mocap, at, at-sim")
    p.add_argument("--save-failures", type=Path, default=None,
                   help="write each unexpected input to DIR/<target>-<i>.bin")
    p.add_argument("--kinds", action="store_true",
                   help="list the kinds of rejection (error messages, numbers blanked)")
    p.add_argument("--atheris", action="store_true", help="coverage-guided fuzzing instead")
    p.add_argument("--atheris-runs", type=int, default=100_000, help="libFuzzer -runs per target")
    args = p.parse_args(argv)
    names = [t.strip() for t in args.targets.split(",") if t.strip()]
    unknown = [t for t in names if t not in TARGETS and t != "at-sim"]
    if unknown:
        p.error(f"unknown target(s): {', '.join(unknown)}")
    if args.atheris:
        return 1 if run_atheris(names, args.atheris_runs, args.seed) else 0
    print(f"fuzz_decoders: {args.inputs} inputs per target, seed {args.seed}, "
          f"python {sys.version.split()[0]}, pid {os.getpid()}")
    results = []
    for name in names:
        res = (run_at_sim(args.inputs, args.seed) if name == "at-sim"
               else run_target(TARGETS[name], args.inputs, args.seed))
        results.append(res)
    return _report(results, args.save_failures, args.kinds)


if __name__ == "__main__":
    sys.exit(main())
