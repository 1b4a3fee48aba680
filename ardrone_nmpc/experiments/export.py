"""``export RUN``: a run directory as one file the robotics viewers open.

* ``mcap`` (the ``mcap`` extra): the channels of :mod:`ardrone_nmpc.runs.channels`, written
  by foxglove-sdk — ``/log`` (one message per row), ``/events``, ``/config`` (JSON, each with
  its JSON schema), ``/pose`` and ``/reference`` (``foxglove.PoseInFrame``), ``/tf``
  (``foxglove.FrameTransform``), ``/flight_path`` and ``/reference_path`` (whole, once) — for
  Foxglove, PlotJuggler or the ``mcap`` CLI. A message's log time is its experiment time
  ``t_s`` (rows and events alike; an event of a flight that never started, ``t_s`` NaN, at the
  origin) on an epoch that puts the run's first row (or an earlier first event) at the
  creation time recorded in ``config.yaml``.
* ``parquet`` (the ``parquet`` extra, pyarrow): the log as one typed table — integer counts,
  categorical labels, saturation flags as booleans, an absolute UTC ``time_utc``, every
  field's unit in its metadata (:mod:`ardrone_nmpc.runs.table_schema`) — with the events
  (JSON lines) and ``config.yaml`` in the file's key-value metadata.

Both keep every float bit for bit (``read_mcap`` reads an MCAP file back). The file is
written beside its final name and renamed into place (:mod:`ardrone_nmpc.core.atomic`): an
export that fails or is interrupted leaves nothing under that name (a previous export there
stays as it was), and nothing but its own temporary file is ever deleted.
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ardrone_nmpc.config.io import config_to_dict
from ardrone_nmpc.core.atomic import atomic_path
from ardrone_nmpc.core.extras import import_extra
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.runs import channels as ch
from ardrone_nmpc.runs import foxglove_channels as fox
from ardrone_nmpc.runs.rundir import CONFIG_FILE, EVENTS_FILE, LOG_FILE, RunData, read_run
from ardrone_nmpc.runs.table_schema import log_table
from ardrone_nmpc.runtime.signals import polled_signals

__all__ = ["EXPORT_FORMATS", "ExportError", "default_output", "export_run", "require_format",
           "write_mcap", "write_parquet", "read_mcap", "McapContents", "run_rows"]

EXPORT_FORMATS = ("mcap", "parquet")
PARQUET_EVENTS_KEY = b"ardrone_nmpc.events"
PARQUET_CONFIG_KEY = b"ardrone_nmpc.config"
_CREATED = re.compile(r"^#\s*created:\s*(\S+)\s*$", re.MULTILINE)


#: The latest MCAP log time: nanoseconds since 1970 in an unsigned 64-bit field.
MAX_LOG_TIME_NS = 2 ** 64 - 1


class ExportError(UserError, ValueError):
    """A user-facing export problem (unknown format, a time MCAP cannot hold): one line."""


def _log_ns(origin_ns: int, t_s: float, where: str) -> int:
    """:func:`~ardrone_nmpc.runs.channels.time_ns`, refusing a time MCAP cannot hold."""
    if math.isfinite(t_s) and origin_ns + t_s * 1e9 > MAX_LOG_TIME_NS:  # before: clamped to 0
        raise _beyond(where, t_s)
    return ch.time_ns(origin_ns, t_s)


def _beyond(where: str, t_s: float) -> ExportError:
    return ExportError(f"{where}: t_s = {t_s!r} s is beyond what an MCAP log time holds "
                       "(nanoseconds since 1970, up to the year 2554); export it as "
                       "--format parquet")


def run_rows(run: RunData) -> list[dict[str, Any]]:
    """The log rows of ``run`` as dicts in column order (floats and str, as read)."""
    names = list(run.columns)
    cols = [run.columns[n].tolist() for n in names]
    return [dict(zip(names, values)) for values in zip(*cols)]


def _created_ns(run: RunData) -> int:
    """The creation time in ``config.yaml``'s header (ns since the epoch); 0 if absent."""
    try:
        m = _CREATED.search((run.path / CONFIG_FILE).read_text(encoding="utf-8"))
        return int(_dt.datetime.fromisoformat(m.group(1)).timestamp() * 1e9) if m else 0
    except (OSError, ValueError):
        return 0


def _origin_ns(run: RunData) -> int:
    """The epoch (ns) of ``t_s = 0``: the first row (or event) falls on the creation time."""
    times = [float(t) for t in run.columns["t_s"][:1]] + [
        float(e["t_s"]) for e in run.events[:1] if isinstance(e.get("t_s"), (int, float))]
    first = min((t for t in times if np.isfinite(t)), default=0.0)
    if min(first, 0.0) * 1e9 < -MAX_LOG_TIME_NS:  # the run would start before 1970 − 584 y
        raise _beyond(f"{run.path}", first)
    return _created_ns(run) - round(min(first, 0.0) * 1e9)


def write_mcap(run: RunData, out: Path) -> int:
    """Write ``run`` as MCAP to ``out`` (foxglove-sdk's writer); return the number of
    messages."""
    fox.sdk("export --format mcap", extra="mcap")
    origin = _origin_ns(run)
    messages: list[tuple[int, int, str, Any]] = []  # (log ns, order, topic, payload)
    paths = ch.PathBuilder()
    for i, row in enumerate(run_rows(run)):
        t_ns = _log_ns(origin, row["t_s"], f"{run.path / LOG_FILE}:{i + 2}")
        for topic, data in ch.row_messages(row, paths):
            messages.append((t_ns, len(messages), topic, data))
    for i, event in enumerate(run.events):  # experiment time, as the rows (read_run moves older runs)
        t = event.get("t_s")
        t_ns = _log_ns(origin, float(t) if isinstance(t, (int, float)) else math.nan,
                       f"{run.path / EVENTS_FILE}: event {i + 1}")
        messages.append((t_ns, len(messages), ch.TOPIC_EVENTS, ch.event_message(event)))
    config = ch.config_message(config_to_dict(run.config), seed=run.seed, version=run.version)
    t0_ns = ch.time_ns(origin, float(run.columns["t_s"][0]) if run.n_rows else 0.0)
    messages.append((t0_ns, -2, ch.TOPIC_CONFIG, config))
    for topic, poses in paths.messages():   # whole paths, shown from the start
        messages.append((t0_ns, -1, topic, poses))
    messages.sort(key=lambda m: m[:2])
    # a Ctrl-C is held while foxglove-sdk's writer runs (landing inside its call back into
    # Python it came out as the writer's I/O error, or as a SystemError) and raised between
    # messages — before atomic_path's end, which then keeps the earlier file
    with atomic_path(out) as tmp, polled_signals() as check, open(tmp, "wb") as stream:
        return fox.write_mcap_messages(stream, _checked(messages, check))


def _checked(messages: list, check, every: int = 256):
    """The ``(log ns, topic, payload)`` of ``messages``, ``check()`` called every ``every``."""
    for i, (t, _, topic, data) in enumerate(messages):
        if i % every == 0:
            check()
        yield t, topic, data


@dataclass
class McapContents:
    """An MCAP file of :func:`write_mcap` read back: messages per topic, in file order; the
    typed (protobuf) messages as plain dicts with the schema's field names."""

    rows: list[dict[str, Any]] = field(default_factory=list)
    row_log_times_ns: list[int] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    event_log_times_ns: list[int] = field(default_factory=list)
    config: dict[str, Any] | None = None
    n_configs: int = 0
    poses: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    schemas: dict[str, str] = field(default_factory=dict)   # topic → schema name
    encodings: dict[str, str] = field(default_factory=dict)   # topic → message encoding


def _as_dict(message) -> dict[str, Any]:
    """A decoded protobuf message as a dict of its fields (all of them, zeros included)."""
    out: dict[str, Any] = {}
    for fd in message.DESCRIPTOR.fields:
        value = getattr(message, fd.name)
        if fd.message_type is not None:   # a message, or a repeated one (no DESCRIPTOR)
            value = (_as_dict(value) if hasattr(value, "DESCRIPTOR")
                     else [_as_dict(v) for v in value])
        out[fd.name] = value
    return out


def read_mcap(path: Path) -> McapContents:
    """Read an exported or recorded MCAP file with the ``mcap`` library (protobuf messages
    through ``mcap-protobuf-support``)."""
    import json

    reader_mod = import_extra("mcap.reader", "mcap", "reading MCAP")
    decoder_mod = import_extra("mcap_protobuf.decoder", "mcap", "reading MCAP")
    out = McapContents()
    factory, decoders = decoder_mod.DecoderFactory(), {}
    with open(path, "rb") as stream:
        reader = reader_mod.make_reader(stream)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            out.schemas[topic] = schema.name if schema is not None else ""
            out.encodings[topic] = channel.message_encoding
            if topic == ch.TOPIC_LOG:
                out.rows.append(ch.decode_row(message.data))
                out.row_log_times_ns.append(message.log_time)
            elif topic == ch.TOPIC_EVENTS:
                out.events.append(json.loads(message.data))
                out.event_log_times_ns.append(message.log_time)
            elif topic == ch.TOPIC_CONFIG:
                out.config = json.loads(message.data)
                out.n_configs += 1
            else:
                if channel.id not in decoders:
                    decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
                decoded = decoders[channel.id](message.data)
                out.poses.setdefault(topic, []).append(_as_dict(decoded))
    return out


def write_parquet(run: RunData, out: Path) -> int:
    """Write the log of ``run`` as a Parquet table to ``out``; return the number of rows."""
    pa = import_extra("pyarrow", "parquet", "export --format parquet")
    pq = import_extra("pyarrow.parquet", "parquet", "export --format parquet")
    table = log_table(pa, run, _origin_ns(run))   # typed columns, units (runs/table_schema)
    events = b"\n".join(ch.event_message(e) for e in run.events)
    config = (run.path / CONFIG_FILE).read_bytes()
    table = table.replace_schema_metadata(
        {**table.schema.metadata, PARQUET_EVENTS_KEY: events, PARQUET_CONFIG_KEY: config})
    # an open stream, not a path: pyarrow deletes a *path* it failed to write
    with atomic_path(out) as tmp, open(tmp, "wb") as stream:
        pq.write_table(table, stream)
    return table.num_rows


#: The module each format is written with (MCAP: foxglove-sdk's writer) and its extra.
_EXTRAS = {"mcap": ("foxglove", "mcap"), "parquet": ("pyarrow.parquet", "parquet")}


def require_format(fmt: str) -> None:
    """Refuse an unknown ``--format``, or one whose library is not installed (one line)."""
    if fmt not in EXPORT_FORMATS:
        raise ExportError(f"--format: unknown format {fmt!r}; choose {', '.join(EXPORT_FORMATS)}")
    module, extra = _EXTRAS[fmt]
    import_extra(module, extra, f"export --format {fmt}")


def default_output(run_dir: Path, fmt: str) -> Path:
    """``<run dir>.<format>`` beside the run directory (``.`` and ``..`` resolved first)."""
    run_dir = Path(run_dir).resolve()
    return run_dir.with_name(f"{run_dir.name}.{fmt}")


def export_run(run_dir: Path, fmt: str, out: Path, *, run: RunData | None = None) -> str:
    """Export the run at ``run_dir`` (or ``run``, read already) as ``fmt`` to ``out``;
    return a one-line report. ``out`` is checked by the caller
    (:func:`~ardrone_nmpc.runs.outputs.check_output_file`)."""
    require_format(fmt)
    run = run if run is not None else read_run(run_dir)
    if fmt == "mcap":
        n = write_mcap(run, out)
        return f"{out}: {n} messages ({run.n_rows} rows, {len(run.events)} events)"
    n = write_parquet(run, out)
    return f"{out}: {n} rows, {len(run.events)} events in the metadata"
