"""A seeded mutation fuzzer for the log readers, shared by ``tests/test_fuzz.py`` and ``benchmarks/fuzz.py``.

Seeds are small logs of every format written here with the project's own writers and the test helpers
(CARMEN via ``write_carmen`` and hand-written ROBOTLASER / RAWLASER / ODOM lines; ROS1 bags with plain, bz2
and lz4 chunks; ROS2 sqlite3 and mcap folders; bare MCAP files with none / zstd / lz4 chunks). Some seeds
carry corrupt message payloads inside a valid container (extreme doubles, huge counts, cut messages, absurd
log times). An input is a seed with a few mutations: byte and bit flips, truncation, chunk duplication and
deletion, 4/8-byte fields overwritten with extreme values, CARMEN line edits (numbers -> 1e300 / nan / inf /
-1 / huge ints, fields added or removed, lines duplicated / deleted / swapped), mutated ``metadata.yaml``
values and types, and compression bombs.

Each input is read in-process through what the CLI uses (``open_log`` + every tick, then ``log_info``) and
classified: ``ok``, ``error`` (a one-line GndReplayError naming the file), ``other`` (any other exception, an
unclear error message, or a tick carrying a value outside the reader contract) or ``hang`` (over the time
bound, via SIGALRM). The peak resident memory of each input is measured by resetting the kernel's
high-water mark (``/proc/self/clear_refs``, after ``malloc_trim`` returns freed heap to the OS) before it
and reading ``VmHWM`` after it: the rise of the resident set, C libraries' buffers included.

Everything is a pure function of (format, index, master seed): the same run gives the same inputs.
"""

from __future__ import annotations

import bz2
import contextlib
import ctypes
import gzip
import math
import os
import random
import re
import resource
import shutil
import signal
import struct
import sys
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, Literal

import numpy as np

TESTS = Path(__file__).resolve().parent
if str(TESTS) not in sys.path:  # the test helpers below are plain modules of this folder
    sys.path.insert(0, str(TESTS))

from test_io_carmen import flaser, make_ticks, odom_line  # noqa: E402
from test_io_rosbag import DT, T0, Msgs, ranges_for, robot, typestore  # noqa: E402

from gndreplay.errors import GndReplayError  # noqa: E402
from gndreplay.info import log_info  # noqa: E402
from gndreplay.io import open_log  # noqa: E402
from gndreplay.io.carmen import write_carmen  # noqa: E402

__all__ = ["FORMATS", "Outcome", "Seeds", "make_input", "memory_guard", "run_input"]

#: Fuzzed formats (the rows of the benchmark table).
FORMATS = ("carmen", "carmen.gz", "carmen.bz2", "ros1", "ros2-db3", "ros2-yaml", "ros2-mcap", "mcap")
Kind = Literal["ok", "error", "other", "hang"]

# reader contract checked on every tick (what downstream stages may rely on)
MAX_ABS_T_NS = 9 * 10**18 // 2
MAX_ABS_XY_M = 1e6
MAX_RANGE_M = 1e5

SPECIAL_TOKENS = (
    "1e300", "-1e300", "1e308", "nan", "NaN", "inf", "-inf", "-1", "0", "99999999999999999999999999",
    "1e20", "4e9", "-9e18", "1e-320", "0x10", "abc", "100000", "100001", "2147483648", "-0",
)  # fmt: skip
SPECIAL_F64 = (1e308, -1e308, 1e300, math.nan, math.inf, -math.inf, 1e20, -1.0, 0.0, 4e9, 5e-324)
SPECIAL_U32 = (0xFFFFFFFF, 0x7FFFFFFF, 0x80000000, 0, 1, 100_000, 0x10000000)
YAML_VALUES = (
    "null", "-1", "99999999999999999999999", "1e300", "'abc'", "[1, 2]", "{a: 1}", "true", "", "nan", "0",
    "-9223372036854775809", "[]", "{}", "'../../etc'", "2.5", "~", "!!binary AAAA", "*x", "&x 1",
)  # fmt: skip


# ---------------------------------------------------------------------------------------------------------
# seeds


def _carmen_seeds(tmp: Path) -> list[bytes]:
    """Small CARMEN logs: the writer's output, and hand-written lines of every scan kind."""
    out = []
    p = tmp / "w.clf"
    write_carmen(p, make_ticks(n=6, beams=31), decimals=3)
    out.append(p.read_bytes())
    lines = "PARAM robot_frontlaser_offset 0.1 h 0\n" + "".join(
        odom_line(f"{i}.05", 0.1 * i) + flaser(f"{i}.1", [1.5, 2.25, 3.0, 81.9, 4.0], odom=(0.1 * i, 0, 0))
        for i in range(1, 7)
    )
    out.append(lines.encode())
    robotlaser = "".join(
        f"ROBOTLASER1 0 -1.5 3.0 1.0 30.0 0.01 0 4 1 2 3 40 2 0 0 {0.1 * i} 0.2 0.1 {0.1 * i} 0 0 "
        f"0.3 0.0 0.5 0.2 0.0 {i}.5 host {i}.5\n"
        f"TRUEPOS {0.1 * i} 0 0 {0.1 * i} 0 0 {i}.4 host {i}.4\n"
        for i in range(1, 7)
    )
    out.append(robotlaser.encode())
    rawlaser = "".join(
        f"RAWLASER1 0 -1.0 2.0 0.5 4.0 0.01 0 5 1.0 2.0 4.5 3.0 NaN 2 0.5 0.6 {i}.25 host 0.1\n"
        for i in range(1, 7)
    )
    out.append(rawlaser.encode())
    azos = "".join(flaser("", [1.0, "NaN", 2.0, 3.0], trailer="0 0 laserazos") for _ in range(6))
    out.append(azos.encode())
    return out


def _write_ros(path: Path, kind: str, rng: random.Random | None, compression: str = "") -> None:
    """A small bag (scan, odom, tf, tf_static, cmd_vel, ground truth); with ``rng``, corrupt payloads."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    ros1 = kind == "ros1"
    ts = typestore(ros1)
    m = Msgs(ts, ros1)
    ser: Callable[[Any, str], bytes] = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    writer: Any
    if ros1:
        writer = Writer1(path)
        if compression:
            writer.set_compression(Writer1.CompressionFormat[compression])
    else:
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
        if compression:
            from rosbags.rosbag2.writer import CompressionFormat, CompressionMode

            writer.set_compression(CompressionMode[compression], CompressionFormat.ZSTD)
    scan_t, odom_t, tf_t, tw_t = (
        "sensor_msgs/msg/LaserScan",
        "nav_msgs/msg/Odometry",
        "tf2_msgs/msg/TFMessage",
        "geometry_msgs/msg/Twist",
    )

    written: set[int] = set()

    def put(conn: Any, t: int, raw: bytes, rate: float = 0.25) -> None:
        first = id(conn) not in written  # the first message of each topic stays intact: opening reads it
        written.add(id(conn))
        if rng is not None and not first and rng.random() < rate:
            raw = _corrupt_payload(raw, rng)
            if rng.random() < 0.2:
                top = (2**32 - 1) * 10**9 + 999_999_999 if ros1 else 2**63 - 1  # the largest each can store
                t = rng.choice((top, top // 2, 1, 0, 2**53 + 1))
        writer.write(conn, t, raw)

    with writer as w:
        c_scan = w.add_connection("/scan", scan_t, typestore=ts)
        c_odom = w.add_connection("/odom", odom_t, typestore=ts)
        c_tf = w.add_connection("/tf", tf_t, typestore=ts)
        c_static = w.add_connection("/tf_static", tf_t, typestore=ts)
        c_cmd = w.add_connection("/cmd_vel", tw_t, typestore=ts)
        c_gt = w.add_connection("/ground_truth", odom_t, typestore=ts)
        put(c_static, T0 - DT, ser(m.tf(T0 - DT, ("base_link", "laser", 0.3, 0.05, 0.1)), tf_t))
        for k in range(7):
            t = T0 - DT // 2 + k * DT
            put(c_odom, t + 1_000_000, ser(m.odom(t, *robot(t)), odom_t))
            # opening reads /tf for the laser mounting (a corrupt one there refuses the bag): rarely corrupt
            put(c_tf, t + 1_000_000, ser(m.tf(t, ("odom", "base_link", *robot(t))), tf_t), 0.03)
        for i in range(6):
            t = T0 + i * DT
            put(c_scan, t + 10_000_000, ser(m.scan(t, ranges_for(i)[:40]), scan_t))
            put(c_cmd, t + 5_000_000, ser(m.twist(0.1 * i, -0.1 * i), tw_t))
            x, _, yaw = robot(t)
            put(c_gt, t, ser(m.odom(t, 2 * x, 1.0, yaw), odom_t))


def _corrupt_payload(raw: bytes, rng: random.Random) -> bytes:
    """One message's bytes with a field overwritten by an extreme value, cut, or flipped."""
    b = bytearray(raw)
    op = rng.randrange(5)
    if op == 0 and len(b) >= 8:
        pos = rng.randrange(0, len(b) - 7)
        b[pos : pos + 8] = struct.pack("<d", rng.choice(SPECIAL_F64))
    elif op == 1 and len(b) >= 4:
        pos = rng.randrange(0, len(b) - 3)
        value = rng.choice(SPECIAL_U32)
        b[pos : pos + 4] = struct.pack("<I", value) if rng.random() < 0.6 else struct.pack("<f", math.nan)
    elif op == 2:
        del b[rng.randrange(0, len(b) + 1) :]
    elif op == 3 and b:
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
    else:
        b = bytearray(rng.randbytes(rng.randrange(0, 64)))
    return bytes(b)


def _rechunk_mcap(src: Path, dst: Path, compression: str) -> None:
    """Copy an MCAP file with another chunk compression (none / zstd / lz4), via the mcap library."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as fh, open(dst, "wb") as out:
        reader = make_reader(fh)
        w = Writer(out, compression=CompressionType[compression], chunk_size=2048)
        w.start(profile="ros2", library="gndreplay-fuzz")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(
                    channel.topic,
                    channel.message_encoding,
                    schemas.get(channel.schema_id, 0),
                    channel.metadata,
                )
            w.add_message(channels[channel.id], message.log_time, message.data, message.publish_time)
        w.finish()


Files = dict[str, bytes | tuple[str, str]]


@dataclass(frozen=True)
class Seed:
    """A log as files (relative path -> bytes) and the path to open."""

    files: Files
    target: str


def _folder(path: Path, name: str) -> Files:
    return {f"{name}/{f.name}": f.read_bytes() for f in sorted(path.iterdir())}


class Seeds:
    """Every seed of every format, written once into ``work`` (a scratch folder)."""

    def __init__(self, work: Path, master_seed: int = 12) -> None:
        work.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix="seeds-", dir=work))
        self.work = work
        self.carmen = _carmen_seeds(work)
        self.ros1: list[Seed] = []
        self.db3: list[Seed] = []
        self.ros2_mcap: list[Seed] = []
        self.mcap: list[Seed] = []
        rng = random.Random(master_seed)
        for i, (comp, corrupt) in enumerate([("", False), ("BZ2", False), ("LZ4", False), ("", True)]):
            p = work / f"r{i}.bag"
            _write_ros(p, "ros1", random.Random(rng.random()) if corrupt else None, comp)
            self.ros1.append(Seed({"log.bag": p.read_bytes()}, "log.bag"))
        for i, (comp, corrupt) in enumerate([("", False), ("MESSAGE", False), ("", True)]):
            p = work / f"s{i}"
            _write_ros(p, "sqlite3", random.Random(rng.random()) if corrupt else None, comp)
            self.db3.append(Seed(_rename_bag(p, "bag"), "bag"))
        for i, corrupt in enumerate([False, True]):
            p = work / f"m{i}"
            _write_ros(p, "mcap", random.Random(rng.random()) if corrupt else None)
            self.ros2_mcap.append(Seed(_rename_bag(p, "bag"), "bag"))
            (inner,) = p.glob("*.mcap")
            for comp in ("NONE", "ZSTD", "LZ4"):
                q = work / f"m{i}-{comp}.mcap"
                _rechunk_mcap(inner, q, comp)
                self.mcap.append(Seed({"log.mcap": q.read_bytes()}, "log.mcap"))

    def payload_input(self, fmt: str, rng: random.Random) -> Seed:
        """A freshly written bag of format ``fmt`` whose message payloads are corrupted by ``rng``."""
        tmp = Path(tempfile.mkdtemp(prefix="payload-", dir=self.work))
        try:
            p = tmp / "b.bag"
            if fmt == "ros1":
                _write_ros(p, "ros1", rng, rng.choice(("", "BZ2", "LZ4")))
                return Seed({"log.bag": p.read_bytes()}, "log.bag")
            storage = "sqlite3" if fmt == "ros2-db3" else "mcap"
            p = tmp / "bag"
            _write_ros(p, storage, rng, rng.choice(("", "MESSAGE")) if storage == "sqlite3" else "")
            if fmt != "mcap":
                return Seed(_rename_bag(p, "bag"), "bag")
            (inner,) = p.glob("*.mcap")
            _rechunk_mcap(inner, tmp / "x.mcap", rng.choice(("NONE", "ZSTD", "LZ4")))
            return Seed({"log.mcap": (tmp / "x.mcap").read_bytes()}, "log.mcap")
        finally:
            shutil.rmtree(tmp)

    def for_format(self, fmt: str) -> list[Seed]:
        if fmt.startswith("carmen"):
            name = "log.clf" + fmt[len("carmen") :]
            return [Seed({name: _compress(name, text)}, name) for text in self.carmen]
        return {
            "ros1": self.ros1,
            "ros2-db3": self.db3,
            "ros2-yaml": self.db3 + self.ros2_mcap[:1],
            "ros2-mcap": self.ros2_mcap,
            "mcap": self.mcap,
        }[fmt]


def _rename_bag(folder: Path, name: str) -> Files:
    """A ROS2 bag folder as files under ``name/`` (file names inside metadata.yaml renamed to match)."""
    files: Files = {}
    old = folder.name
    for f in sorted(folder.iterdir()):
        data = f.read_bytes()
        if f.name == "metadata.yaml":
            data = data.replace(old.encode(), name.encode())
        files[f"{name}/{f.name.replace(old, name)}"] = data
    return files


def _compress(name: str, data: bytes) -> bytes:
    if name.endswith(".gz"):
        return gzip.compress(data, mtime=0)
    if name.endswith(".bz2"):
        return bz2.compress(data)
    return data


# ---------------------------------------------------------------------------------------------------------
# mutations


def _bytes_mutation(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    op = rng.randrange(7)
    if not b:
        return bytes(rng.randbytes(rng.randrange(1, 32)))
    if op == 0:  # byte flips
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif op == 1:  # bit flips
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
    elif op == 2:  # truncation
        del b[rng.randrange(len(b)) :]
    elif op == 3:  # chunk duplication
        a = rng.randrange(len(b))
        n = rng.randint(1, min(512, len(b) - a))
        b[a:a] = b[a : a + n] * rng.randint(1, 3)
    elif op == 4:  # chunk deletion
        a = rng.randrange(len(b))
        del b[a : a + rng.randint(1, 256)]
    elif op == 5 and len(b) >= 8:  # an 8-byte field (length, time, double) overwritten
        pos = rng.randrange(len(b) - 7)
        if rng.random() < 0.5:
            b[pos : pos + 8] = struct.pack("<Q", rng.choice((2**64 - 1, 2**63, 2**40, 0, 2**32 + 7)))
        else:
            b[pos : pos + 8] = struct.pack("<d", rng.choice(SPECIAL_F64))
    elif len(b) >= 4:  # a 4-byte field (length, count, float)
        pos = rng.randrange(len(b) - 3)
        b[pos : pos + 4] = struct.pack("<I", rng.choice(SPECIAL_U32))
    return bytes(b)


def _line_mutation(text: bytes, rng: random.Random) -> bytes:
    lines = text.split(b"\n")
    if not lines:
        return text
    i = rng.randrange(len(lines))
    tok = lines[i].split(b" ")
    op = rng.randrange(8)
    if op <= 2 and len(tok) > 1:  # a field replaced by an extreme / invalid number
        j = rng.randrange(1, len(tok))
        tok[j] = rng.choice(SPECIAL_TOKENS).encode()
    elif op == 3:  # a field added
        tok.insert(rng.randrange(1, len(tok) + 1), rng.choice((b"1.5", b"0", b"nan", tok[-1])))
    elif op == 4 and len(tok) > 1:  # a field removed
        del tok[rng.randrange(1, len(tok))]
    elif op == 5:  # a line duplicated or deleted
        if rng.random() < 0.5:
            lines.insert(i, lines[i])
        else:
            del lines[i]
        return b"\n".join(lines)
    elif op == 6 and len(lines) > 1:  # two lines swapped
        k = rng.randrange(len(lines))
        lines[i], lines[k] = lines[k], lines[i]
        return b"\n".join(lines)
    else:  # the message name replaced
        tok[0] = rng.choice(
            (b"FLASER", b"ODOM", b"ROBOTLASER1", b"RAWLASER2", b"TRUEPOS", b"PARAM", b"RLASER")
        )
    lines[i] = b" ".join(tok)
    return b"\n".join(lines)


def _yaml_mutation(text: bytes, rng: random.Random) -> bytes:
    lines = text.split(b"\n")
    keyed = [i for i, ln in enumerate(lines) if re.match(rb"^\s*-?\s*[A-Za-z_]+:", ln)]
    op = rng.randrange(5)
    if keyed and op <= 2:  # a value of another type
        i = rng.choice(keyed)
        key = lines[i].split(b":", 1)[0]
        lines[i] = key + b": " + rng.choice(YAML_VALUES).encode()
    elif keyed and op == 3:  # a key removed
        del lines[rng.choice(keyed)]
    else:
        return _bytes_mutation(text, rng)
    return b"\n".join(lines)


def _bomb(name: str, rng: random.Random) -> bytes:
    """A compressed file of zeros (or of one endless line): tiny on disk, large when read."""
    size = rng.choice((1 << 20, 8 << 20, 24 << 20))
    body = b"\0" * size if rng.random() < 0.5 else b"FLASER 3 " + b"1 " * (size // 2)
    return _compress(name, body)


def make_input(seeds: Seeds, fmt: str, index: int, master_seed: int = 12) -> Seed:
    """Input ``index`` of format ``fmt``: a seed with 1-4 mutations (a pure function of the arguments)."""
    rng = random.Random(f"{master_seed}:{fmt}:{index}")
    base = rng.choice(seeds.for_format(fmt))
    files = dict(base.files)
    if fmt.startswith("carmen"):
        (name,) = files
        if fmt != "carmen" and rng.random() < 0.04:
            return Seed({name: _bomb(name, rng)}, name)
        text = seeds.carmen[seeds.for_format(fmt).index(base)]
        compressed_level = fmt != "carmen" and rng.random() < 0.4
        if not compressed_level:
            for _ in range(rng.randint(1, 4)):
                text = _line_mutation(text, rng) if rng.random() < 0.7 else _bytes_mutation(text, rng)
            files[name] = _compress(name, text)
        else:
            data = files[name]
            for _ in range(rng.randint(1, 3)):
                data = _bytes_mutation(data, rng)
            files[name] = data
        return Seed(files, name)
    if fmt == "ros2-yaml":
        key = f"{base.target}/metadata.yaml"
        data = files[key]
        for _ in range(rng.randint(1, 3)):
            data = _yaml_mutation(data, rng)
        files[key] = data
        return Seed(files, base.target)
    if rng.random() < 0.3:  # corrupt payloads inside a valid container
        return seeds.payload_input(fmt, rng)
    # the container file (the bag, the .db3, the .mcap)
    key = max((k for k in files if not k.endswith("metadata.yaml")), key=lambda k: len(files[k]))
    data = files[key]
    for _ in range(rng.randint(1, 4)):
        data = _bytes_mutation(data, rng)
    files[key] = data
    return Seed(files, base.target)


# ---------------------------------------------------------------------------------------------------------
# running one input


@dataclass(frozen=True)
class Outcome:
    """How one input was handled."""

    fmt: str
    index: int
    kind: Kind
    detail: str
    peak_mb: float
    seconds: float


class _Timeout(BaseException):
    """Raised by SIGALRM when an input runs over its time bound (not an Exception: nothing catches it)."""


def _on_alarm(signum: int, frame: FrameType | None) -> None:
    raise _Timeout()


def _status_kb(field: str) -> int | None:
    try:
        text = Path("/proc/self/status").read_text()
    except OSError:
        return None
    m = re.search(rf"^{field}:\s+(\d+) kB", text, re.MULTILINE)
    return int(m.group(1)) if m else None


def _reset_peak() -> bool:
    """Give freed heap back to the OS (so reuse of it shows as a rise) and reset the kernel's ``VmHWM``."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


@contextlib.contextmanager
def memory_guard(extra_bytes: int = 3 << 30) -> Iterator[None]:
    """Cap the address space at its current size + ``extra_bytes`` (a runaway input gets a MemoryError
    instead of taking the shared machine down); restores the previous limit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    vm = _status_kb("VmSize")
    if vm is None:
        yield
        return
    cap = vm * 1024 + extra_bytes
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def check_tick(tick: Any) -> None:
    """The reader contract every downstream stage relies on (AssertionError naming the broken value)."""
    scan = tick.scan
    assert isinstance(tick.t_ns, int) and abs(tick.t_ns) <= MAX_ABS_T_NS, f"tick time {tick.t_ns}"
    assert tick.t_ns == scan.t_ns, "tick and scan times differ"
    for name, p in (("odom", tick.odom), ("truth", tick.truth), ("sensor pose", scan.sensor_pose)):
        if p is not None:
            ok = abs(p.x) < MAX_ABS_XY_M and abs(p.y) < MAX_ABS_XY_M and -math.pi <= p.theta <= math.pi
            assert ok, f"{name} {p}"
    if tick.cmd is not None:
        c = tick.cmd
        assert all(math.isfinite(v) for v in (c.v_mps, c.w_radps, c.vy_mps)), f"command {c}"
    assert 0.0 <= scan.min_range_m < scan.max_range_m <= MAX_RANGE_M, f"range limits {scan.max_range_m}"
    r, a = scan.ranges_m, scan.angles_rad
    assert r.dtype == np.float64 and r.ndim == 1 and r.shape == a.shape and r.size > 0, "scan arrays"
    assert bool(np.all(np.isfinite(a))), "non-finite bearing"
    hits = r[np.isfinite(r)]
    assert bool(np.all((hits >= 0.0) & (hits < scan.max_range_m))), "hit beyond the max range"


def _read(path: Path) -> None:
    """What ``gndreplay run`` / ``info`` do with a log: every tick, the description, the report, info."""
    with warnings.catch_warnings():  # a warning leaking from a reader counts as a failure, as in the suite
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        with open_log(path) as log:
            for tick in log.ticks():
                check_tick(tick)
            log.describe()
            _ = log.report
        log_info(path)


def _write_input(seed: Seed, work: Path) -> None:
    """The input's files under ``work`` (emptied first): bytes, or ("fifo" | "dir", "") / ("symlink",
    target) entries; a link target starting with fuzz_files.DECOY points into ``work``'s sibling "decoy"."""
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    for rel, data in seed.files.items():
        path = work / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(data, bytes):
            path.write_bytes(data)
        elif data[0] == "fifo":
            os.mkfifo(path)
        elif data[0] == "dir":
            path.mkdir()
        else:
            path.symlink_to(data[1].replace("@DECOY@", str(work.parent / "decoy")))


def _redraw(seed: Seed, index: int) -> bool:
    """Whether a run-folder input is also redrawn by ``build_report`` (see fuzz_files)."""
    marker = seed.files.get(f"{seed.target}/.gndreplay")
    planted = any(not isinstance(v, bytes) for v in seed.files.values())
    return index % 10 == 0 or planted or not isinstance(marker, bytes) or b"decoy" in marker


def run_input(seed: Seed, fmt: str, index: int, work: Path, *, timeout_s: float = 20.0) -> Outcome:
    """Write the input into ``work`` (emptied first), read it, classify it (see the module docstring)."""
    _write_input(seed, work)
    target = work / seed.target
    rss0 = _status_kb("VmRSS") or 0
    has_peak = _reset_peak()
    old = signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    t0 = time.perf_counter()
    kind: Kind
    try:
        try:
            if fmt in FORMATS:
                _read(target)
            else:
                import fuzz_files

                fuzz_files.read_file_input(fmt, target, _redraw(seed, index))
            kind, detail = "ok", ""
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
    except _Timeout:
        kind, detail = "hang", f"over {timeout_s:g} s"
    except GndReplayError as err:
        text = str(err)
        if "\n" in text or seed.target.split("/")[0] not in text:
            kind, detail = "other", f"unclear message: {text[:300]!r}"
        else:
            kind, detail = "error", text
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as err:  # classifying every other exception is the point
        frames = traceback.extract_tb(err.__traceback__)
        where = next(
            (f"{Path(f.filename).name}:{f.lineno}" for f in reversed(frames) if "gndreplay" in f.filename),
            "?",
        )
        kind, detail = "other", f"{type(err).__name__} at {where}: {str(err)[:200]}"
    seconds = time.perf_counter() - t0
    peak = _status_kb("VmHWM") if has_peak else None
    peak_mb = max(0.0, ((peak or rss0) - rss0) / 1024.0)
    return Outcome(fmt, index, kind, detail, peak_mb, seconds)
