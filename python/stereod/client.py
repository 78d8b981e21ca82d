"""Client of the stereod socket protocol, version 1 (docs/protocol.md).

Outcomes and errors
-------------------
Robot code wants a distance, or a clear "no reading" it can act on (slow down, stop),
without exception handling around every call. So:

- :meth:`Client.distance` always returns a :class:`Reading`. ``reading.valid`` is true
  when ``reading.distance_m`` holds a distance; otherwise ``reading.reason`` (a stable
  code from docs/protocol.md, such as ``too_few_valid_pixels``, ``nearer_than_range``,
  ``stale``, ``source_down``) and ``reading.message`` say why. A stale reading is one of
  these normal outcomes; pass ``raise_stale=True`` to get :class:`StaleReading` instead.
- Exceptions are for what the robot's code cannot treat as a reading:
  :class:`ServiceUnavailable` (no socket, connection refused or lost, no reply in time,
  the service refusing the connection) and :class:`ProtocolError` (an error reply such
  as ``unknown_command`` or ``bad_request``, or a reply this client cannot parse).

All exceptions derive from :class:`StereodError`.

Failing closed
--------------
A reply is checked before it is believed: a reading that says ``valid`` without a
finite, positive ``distance_m`` (NaN, ``Infinity``, a string, ``null``, a negative
number) is a :class:`ProtocolError`, never a valid :class:`Reading`, so "stop if the
distance is below 0.5 m" cannot be skipped by a reply that is not a number. A payload
may claim at most :data:`MAX_PAYLOAD_BYTES` and is read as it arrives (a claimed size is
never allocated up front), and ``timeout_s`` bounds a whole request, its reply and its
payloads, not each read: a service trickling a byte at a time cannot hold a call longer.

Connections
-----------
A :class:`Client` opens its connection on first use and opens a new one on the next call
after a connection was lost, so a long-running program keeps one client and survives a
service restart (the call during the outage raises :class:`ServiceUnavailable`). Each
:meth:`Client.subscribe` generator uses a connection of its own, so the client stays
usable for requests while a subscription runs. A client is not thread-safe: use one per
thread.
"""

from __future__ import annotations

import json
import math
import socket
import time
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np

DEFAULT_SOCKET_PATH = "/run/stereod/stereod.sock"

#: Items :meth:`Client.snapshot` asks for by default, each only when the service offers it
#: (``hello``'s ``snapshot_items``): ``confidence`` comes when the service has it.
DEFAULT_SNAPSHOT_ITEMS: Tuple[str, ...] = ("depth", "disparity", "left", "cloud", "confidence")

#: Reading reasons of the class "no data": the service runs, but this frame's region gave
#: no distance (docs/protocol.md, the reading object).
NO_DATA_REASONS = frozenset(
    {"too_few_valid_pixels", "nothing_in_range", "bad_frame", "nearer_than_range"}
)
#: Reading reasons of the class "not producing": no current frame to measure from.
NOT_PRODUCING_REASONS = frozenset(
    {"out_of_sync", "source_down", "stale", "no_frame_yet", "uncalibrated"}
)

# Error codes after which the service closes the connection.
_CLOSING_CODES = frozenset({"too_many_clients", "not_allowed", "idle_timeout", "request_too_large"})
# Error codes that mean "you cannot be served now" rather than "your request is wrong".
_UNAVAILABLE_CODES = frozenset({"too_many_clients", "not_allowed", "idle_timeout"})

# A reply line longer than this is treated as malformed (replies are small; images travel
# as binary payloads).
_MAX_LINE_BYTES = 16 * 1024 * 1024

#: The largest binary payload a reply may claim: the point cloud of an 8192x8192 frame
#: (16 bytes a point). A claim above it is a :class:`ProtocolError`.
MAX_PAYLOAD_BYTES = 1 << 30

# Bytes asked of the socket at a time.
_RECV_BYTES = 1 << 20

Json = Dict[str, Any]


class StereodError(Exception):
    """Base of every exception this package raises."""


class ServiceUnavailable(StereodError):
    """The service cannot be reached or served no reply: no socket file, connection
    refused or denied, connection lost, no reply within the timeout, or the service
    refused the connection (``too_many_clients``, ``not_allowed``, ``idle_timeout``;
    then :attr:`code` holds that code, else ``None``)."""

    def __init__(self, message: str, code: Optional[str] = None) -> None:
        super().__init__(message)
        self.message = message
        self.code = code


class ProtocolError(StereodError):
    """The service answered with an error (:attr:`code` is the protocol's stable code,
    e.g. ``unknown_command``, ``bad_request``, ``not_available``; :attr:`message` is for
    people), or sent something this client cannot parse (:attr:`code` ``malformed``)."""

    def __init__(self, code: str, message: str, reply: Optional[Json] = None) -> None:
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message
        self.reply = reply


class StaleReading(StereodError):
    """Raised by :meth:`Client.distance` with ``raise_stale=True`` when the newest reading
    is older than allowed. :attr:`reading` is the stale reading (its ``age_ms``,
    ``stamp_ns`` and ``frame`` say how old it is)."""

    def __init__(self, reading: "Reading") -> None:
        super().__init__(reading.message or "the newest reading is older than allowed")
        self.reading = reading


def _opt_float(value: Any) -> Optional[float]:
    """A JSON number that is finite, or None for null; anything else raises ValueError."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{value!r} is not a number")
    if not math.isfinite(value):
        raise ValueError(f"{value!r} is not a finite number")
    return float(value)


def _opt_int(value: Any) -> Optional[int]:
    """A JSON integer, or None for null; anything else raises ValueError."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{value!r} is not an integer")
    return value


def _reject_constant(name: str) -> Any:
    # json.loads takes NaN, Infinity and -Infinity by default; no reply of the protocol
    # holds them, and a distance that is one must never pass for a number.
    raise ValueError(f"{name} is not JSON")


@dataclass
class Reading:
    """The reading object of docs/protocol.md.

    ``valid`` is true when ``distance_m`` (metres, to the nearest object in the region of
    interest) holds a distance. When it is false, ``reason`` is the stable code and
    ``message`` the text for people. Fields the reply did not carry are ``None``
    (``stamp_ns``, ``age_ms`` and ``frame`` are absent before the first frame).
    """

    valid: bool
    distance_m: Optional[float] = None
    stamp_ns: Optional[int] = None
    age_ms: Optional[float] = None
    frame: Optional[int] = None
    valid_fraction: Optional[float] = None
    in_range_fraction: Optional[float] = None
    region_pixels: Optional[int] = None
    range_limit_fraction: Optional[float] = None
    inferred_fraction: Optional[float] = None
    #: Of the region, the share whose columns cannot see as near as the distance (the
    #: image's left edge): a surface that near there would go unseen. ``None`` when the
    #: whole region sees that near (the service leaves the field out).
    out_of_view_fraction: Optional[float] = None
    #: Why there is no reading (a code of docs/protocol.md), ``None`` when valid.
    reason: Optional[str] = None
    #: The reason in words, for logs and people; may change between versions.
    message: Optional[str] = None
    #: With reason ``nearer_than_range``: the obstacle is nearer than this (metres).
    nearer_than_m: Optional[float] = None
    #: The closest depth the matcher measures, metres (``None`` from older services).
    closest_m: Optional[float] = None
    #: Whether the matcher looks for something nearer than its range (census-sgm).
    near_field_guard: Optional[bool] = None
    #: The capture time of the pair on the service machine's CLOCK_REALTIME (ns since the
    #: Unix epoch): the stamp to merge with other robot data; ``stamp_ns`` is the same
    #: instant on CLOCK_MONOTONIC.
    stamp_realtime_ns: Optional[int] = None
    #: The service suspects its calibration (its health check finds the rows of the two
    #: images apart): a valid distance may be wrong. ``stereoctl distance`` exits 4 for it.
    calibration_suspect: bool = False
    #: With ``calibration_suspect``: how far apart the rows are (pixels).
    calibration_row_offset_px: Optional[float] = None
    #: Subscriptions only: events the service skipped before this one.
    skipped: int = 0
    #: The JSON object as received, with any fields this class does not name.
    raw: Json = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_json(cls, obj: Any, skipped: int = 0) -> "Reading":
        """Builds a reading from its JSON object; :class:`ProtocolError` when it is not one."""
        if not isinstance(obj, dict) or not isinstance(obj.get("valid"), bool):
            raise ProtocolError("malformed", f"not a reading object: {obj!r}")
        distance = obj.get("distance_m")
        if obj["valid"] and (isinstance(distance, bool) or not isinstance(distance, (int, float))
                             or not math.isfinite(distance) or distance <= 0):
            # Fail closed: a "valid" reading whose distance is not a positive number would
            # pass every "closer than" check a robot makes.
            raise ProtocolError(
                "malformed", f"a valid reading without a finite positive distance_m: {obj!r}")
        reason = obj.get("reason")
        code = message = None
        if isinstance(reason, dict):
            code = reason.get("code")
            message = reason.get("message")
        elif isinstance(reason, str):
            code = reason
        try:
            return cls(
                valid=obj["valid"],
                distance_m=_opt_float(obj.get("distance_m")),
                stamp_ns=_opt_int(obj.get("stamp_ns")),
                age_ms=_opt_float(obj.get("age_ms")),
                frame=_opt_int(obj.get("frame")),
                valid_fraction=_opt_float(obj.get("valid_fraction")),
                in_range_fraction=_opt_float(obj.get("in_range_fraction")),
                region_pixels=_opt_int(obj.get("region_pixels")),
                range_limit_fraction=_opt_float(obj.get("range_limit_fraction")),
                inferred_fraction=_opt_float(obj.get("inferred_fraction")),
                out_of_view_fraction=_opt_float(obj.get("out_of_view_fraction")),
                reason=code,
                message=message,
                nearer_than_m=_opt_float(obj.get("nearer_than_m")),
                closest_m=_opt_float(obj.get("closest_m")),
                near_field_guard=(
                    bool(obj["near_field_guard"]) if "near_field_guard" in obj else None
                ),
                stamp_realtime_ns=_opt_int(obj.get("stamp_realtime_ns")),
                calibration_suspect=bool(obj.get("calibration_suspect", False)),
                calibration_row_offset_px=_opt_float(obj.get("calibration_row_offset_px")),
                skipped=int(skipped or 0),
                raw=obj,
            )
        except (TypeError, ValueError) as error:
            raise ProtocolError("malformed", f"bad reading object {obj!r}: {error}") from None

    @property
    def stale(self) -> bool:
        """True when the reading was withheld for being older than allowed."""
        return self.reason == "stale"

    @property
    def producing(self) -> bool:
        """False when the service has no current frame to measure from (reasons
        ``out_of_sync``, ``source_down``, ``stale``, ``no_frame_yet``, ``uncalibrated``);
        true for a valid reading and for the "no data" reasons."""
        return self.reason not in NOT_PRODUCING_REASONS


class Snapshot(Dict[str, np.ndarray]):
    """The arrays of a snapshot, keyed by item name, with the reply's metadata as
    attributes.

    - ``depth``: float32 metres, H x W, NaN where the service has no depth;
    - ``disparity``: float32 pixels, H x W, +inf where there is none;
    - ``left``, ``raw_left``, ``raw_right``: uint8, H x W;
    - ``cloud``: float32, N x 4 (x, y, z in metres in the rectified left camera:
      x right, y down, z forward; intensity 0..255);
    - ``left_colour``, ``raw_left_colour``, ``raw_right_colour``: uint8, H x W x 3, red
      first (0 x 0 x 3 when the camera keeps no colour);
    - ``cloud_colour``: uint8, N x 3, red first, one row per ``cloud`` point in its order
      (0 rows for a grey source);
    - other items (e.g. ``confidence``): uint8 H x W for one byte per pixel, else the
      payload's bytes as a flat uint8 array.
    """

    frame: Optional[int]
    stamp_ns: Optional[int]
    depth_valid: Optional[bool]
    reading: Optional[Reading]
    calibration: Json
    payloads: List[Json]
    header: Json

    def __init__(self, header: Json, arrays: Dict[str, np.ndarray]) -> None:
        super().__init__(arrays)
        self.header = header
        self.frame = _opt_int(header.get("frame"))
        self.stamp_ns = _opt_int(header.get("stamp_ns"))
        self.depth_valid = header.get("depth_valid")
        reading = header.get("reading")
        self.reading = Reading.from_json(reading) if reading is not None else None
        self.calibration = header.get("calibration") or {}
        self.payloads = list(header.get("payloads") or [])


_FORMATS: Dict[str, Tuple[str, int]] = {
    # format: (numpy dtype, values per element)
    "u16_mm": ("<u2", 1),
    "f32_m": ("<f4", 1),
    "f32_px": ("<f4", 1),
    "u8_gray": ("u1", 1),
    "f32_xyzi": ("<f4", 4),
}


def decode_payload(descriptor: Json, data: Union[bytes, bytearray, memoryview]) -> np.ndarray:
    """Turns one binary payload into a numpy array, after its descriptor (``format``,
    ``width``, ``height`` or ``points``, ``bytes``). ``u16_mm`` and ``f32_m`` become
    float32 metres with NaN for 0 (invalid); see :class:`Snapshot` for the others."""
    fmt = descriptor.get("format")
    size = len(data)
    if descriptor.get("bytes") is not None and int(descriptor["bytes"]) != size:
        raise ProtocolError("malformed", f"payload of {size} bytes, descriptor says {descriptor}")
    width = int(descriptor.get("width") or 0)
    height = int(descriptor.get("height") or 0)
    if fmt == "f32_xyzi":
        if size % 16:
            raise ProtocolError("malformed", f"f32_xyzi payload of {size} bytes is not N x 16")
        return np.frombuffer(data, dtype="<f4").reshape(-1, 4)
    if fmt == "u8_rgb":
        # Colour: an image (height x width x 3) or, with ``points``, one colour per cloud
        # point (N x 3), red first. A grey source sends an empty one.
        if "points" in descriptor:
            points = int(descriptor.get("points") or 0)
            if points * 3 != size:
                raise ProtocolError(
                    "malformed", f"u8_rgb payload of {size} bytes is not {points} points x 3")
            return np.frombuffer(data, dtype=np.uint8).reshape(points, 3)
        if size == 0:
            return np.zeros((0, 0, 3), dtype=np.uint8)
        if width * height * 3 != size:
            raise ProtocolError(
                "malformed", f"u8_rgb payload of {size} bytes is not {width}x{height}x3")
        return np.frombuffer(data, dtype=np.uint8).reshape(height, width, 3)
    if fmt in _FORMATS:
        dtype = np.dtype(_FORMATS[fmt][0])
        if size == 0:
            pixels = np.zeros((0, 0), dtype=dtype)
        elif width * height * dtype.itemsize != size:
            raise ProtocolError(
                "malformed", f"{fmt} payload of {size} bytes is not {width}x{height}")
        else:
            pixels = np.frombuffer(data, dtype=dtype).reshape(height, width)
        if fmt == "u16_mm":
            metres = pixels.astype(np.float32) / np.float32(1000.0)
            metres[pixels == 0] = np.nan
            return metres
        if fmt == "f32_m":
            metres = pixels.copy()
            metres[pixels == 0] = np.nan
            return metres
        return pixels
    # A format this client does not know (a newer service): one byte per pixel as an
    # image, anything else as bytes.
    raw = np.frombuffer(data, dtype=np.uint8)
    if width > 0 and height > 0 and width * height == size:
        return raw.reshape(height, width)
    return raw


class _Connection:
    """One socket with its own buffered reader: JSON lines and binary payloads, each read
    to a deadline (the socket's timeout is set to what is left before every receive)."""

    def __init__(self, path: str, timeout_s: Optional[float]) -> None:
        self.path = path
        self.timeout_s = timeout_s
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(timeout_s)
        try:
            self.sock.connect(path)
        except FileNotFoundError:
            self.sock.close()
            raise ServiceUnavailable(f"no service socket at {path}") from None
        except (socket.timeout, OSError) as error:
            self.sock.close()
            raise ServiceUnavailable(f"cannot connect to {path}: {error}") from None
        self._buffer = bytearray()  # received and not yet handed out
        # The deadline of the request last answered: its payloads are read by it too.
        self.reply_deadline: Optional[float] = None
        self.hello: Optional[Json] = None
        self.used = False

    def close(self) -> None:
        self.sock.close()

    def deadline(self, timeout_s: Optional[float] = None) -> Optional[float]:
        """The time.monotonic() by which a wait of ``timeout_s`` (default: the client's)
        must end; None: no limit."""
        limit = self.timeout_s if timeout_s is None else timeout_s
        return None if limit is None else time.monotonic() + limit

    def send(self, request: Json) -> None:
        line = json.dumps(request, separators=(",", ":")).encode("utf-8") + b"\n"
        try:
            self.sock.settimeout(self.timeout_s)
            self.sock.sendall(line)
        except (socket.timeout, OSError) as error:
            raise ServiceUnavailable(f"connection to {self.path} lost: {error}") from None

    def _receive(self, deadline: Optional[float], most: int) -> bytes:
        """At most ``most`` bytes, waiting no later than ``deadline``; b"" when the service
        closed the connection."""
        if deadline is None:
            self.sock.settimeout(None)
        else:
            left = deadline - time.monotonic()
            if left <= 0:
                raise socket.timeout()
            self.sock.settimeout(left)
        return self.sock.recv(most)

    def read_line(self, deadline: Optional[float]) -> Json:
        searched = 0  # the buffer holds no newline before this
        try:
            while True:
                newline = self._buffer.find(b"\n", searched)
                if newline >= 0:
                    line = bytes(self._buffer[:newline + 1])
                    del self._buffer[:newline + 1]
                    break
                searched = len(self._buffer)
                if searched >= _MAX_LINE_BYTES:
                    raise ProtocolError("malformed", f"reply line longer than {_MAX_LINE_BYTES} bytes")
                chunk = self._receive(deadline, _RECV_BYTES)
                if not chunk:
                    if self._buffer:
                        raise ServiceUnavailable(
                            f"the service closed the connection in the middle of a reply ({self.path})")
                    raise ServiceUnavailable(f"the service closed the connection ({self.path})")
                self._buffer += chunk
        except socket.timeout:
            raise ServiceUnavailable(f"no reply from {self.path} in time") from None
        except OSError as error:
            raise ServiceUnavailable(f"connection to {self.path} lost: {error}") from None
        try:
            obj = json.loads(line, parse_constant=_reject_constant)
        except ValueError as error:
            raise ProtocolError("malformed", f"reply is not JSON ({error}): {line[:200]!r}") from None
        if not isinstance(obj, dict):
            raise ProtocolError("malformed", f"reply is not a JSON object: {line[:200]!r}")
        return obj

    def read_bytes(self, count: int, deadline: Optional[float]) -> bytearray:
        """``count`` bytes, grown as they arrive: memory follows what the service sends,
        not what it claims."""
        out = self._buffer[:count]
        del self._buffer[:count]
        try:
            while len(out) < count:
                chunk = self._receive(deadline, min(count - len(out), _RECV_BYTES))
                if not chunk:
                    raise ServiceUnavailable(
                        f"the service closed the connection in a payload ({len(out)} of {count} bytes)")
                out += chunk
        except socket.timeout:
            raise ServiceUnavailable(f"payload from {self.path} not received in time") from None
        except OSError as error:
            raise ServiceUnavailable(f"connection to {self.path} lost: {error}") from None
        return out

    def read_payloads(self, descriptors: Sequence[Json], deadline: Optional[float]) -> List[bytearray]:
        counts = []
        for descriptor in descriptors:
            try:
                count = _opt_int(descriptor["bytes"])
            except (KeyError, TypeError, ValueError):
                raise ProtocolError("malformed", f"payload without a size: {descriptor!r}") from None
            if count is None or count < 0:
                raise ProtocolError("malformed", f"payload without a size: {descriptor!r}")
            if count > MAX_PAYLOAD_BYTES:
                raise ProtocolError(
                    "malformed", f"payload of {count} bytes, more than {MAX_PAYLOAD_BYTES} "
                    f"(MAX_PAYLOAD_BYTES): {descriptor!r}")
            counts.append(count)
        return [self.read_bytes(count, deadline) for count in counts]


def _check(reply: Json) -> Json:
    """Raises for an error reply; returns the reply otherwise."""
    ok = reply.get("ok")
    if ok is True:
        return reply
    if ok is False:
        error = reply.get("error") if isinstance(reply.get("error"), dict) else {}
        code = str(error.get("code", "malformed"))
        message = str(error.get("message", ""))
        if code in _UNAVAILABLE_CODES:
            raise ServiceUnavailable(f"{code}: {message}", code=code)
        raise ProtocolError(code, message, reply)
    raise ProtocolError("malformed", f"reply without \"ok\": {reply!r}", reply)


def _decode_all(descriptors: Sequence[Json], blobs: Sequence[bytearray]) -> Dict[str, np.ndarray]:
    arrays: Dict[str, np.ndarray] = {}
    for index, (descriptor, blob) in enumerate(zip(descriptors, blobs)):
        name = str(descriptor.get("name", f"payload{index}"))
        arrays[name] = decode_payload(descriptor, blob)
    return arrays


class Client:
    """A connection to the stereod service.

    ``socket_path`` is the service's Unix socket; ``timeout_s`` bounds connecting and
    each request as a whole, its reply line and its payloads (``None``: wait
    indefinitely). Usable as a context manager,
    which closes the connection at the end::

        with Client("/run/stereod/stereod.sock") as client:
            print(client.distance())
    """

    def __init__(self, socket_path: str = DEFAULT_SOCKET_PATH, timeout_s: Optional[float] = 5.0) -> None:
        self.socket_path = socket_path
        self.timeout_s = timeout_s
        self._connection: Optional[_Connection] = None

    # -- connection --------------------------------------------------------------------

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    def connect(self) -> None:
        """Opens the connection now (it is otherwise opened by the first call).
        :class:`ServiceUnavailable` when the service cannot be reached."""
        if self._connection is None:
            self._connection = _Connection(self.socket_path, self.timeout_s)

    def close(self) -> None:
        """Closes the connection; the next call opens a new one."""
        connection, self._connection = self._connection, None
        if connection is not None:
            connection.close()

    def _exchange(self, request: Json) -> Tuple[Json, _Connection]:
        """Sends one request and reads its reply line (not checked). Reconnects and
        retries once when a connection that was idle turns out closed by the service."""
        for attempt in (0, 1):
            self.connect()
            connection = self._connection
            assert connection is not None
            reused = connection.used
            connection.used = True
            try:
                deadline = connection.deadline()
                connection.send(request)
                reply = connection.read_line(deadline)
            except ServiceUnavailable:
                self.close()
                if reused and attempt == 0:
                    continue
                raise
            except BaseException:
                self.close()
                raise
            error = reply.get("error") if reply.get("ok") is False else None
            code = error.get("code") if isinstance(error, dict) else None
            if code in _CLOSING_CODES:
                self.close()
                if code == "idle_timeout" and reused and attempt == 0:
                    continue
            connection.reply_deadline = deadline
            return reply, connection
        raise AssertionError("unreachable")

    def request(self, request: Json) -> Json:
        """Sends any request object and returns its reply (``ok`` true). For commands
        without a binary payload; :class:`ProtocolError` for an error reply."""
        reply, _ = self._exchange(request)
        if reply.get("payloads") or reply.get("bytes"):
            self.close()  # the payload cannot be skipped reliably: start afresh
            raise ProtocolError("malformed", "reply with a binary payload: use snapshot()", reply)
        return _check(reply)

    # -- commands ----------------------------------------------------------------------

    def hello(self) -> Json:
        """The service's identity and abilities: ``service``, ``version``, ``protocol``,
        ``commands``, ``streams``, ``snapshot_items``, ``calibrated``."""
        reply = self.request({"cmd": "hello"})
        if self._connection is not None:
            self._connection.hello = reply
        return {k: v for k, v in reply.items() if k != "ok"}

    def distance(self, max_age_ms: Optional[float] = None, raise_stale: bool = False) -> Reading:
        """The nearest-object distance now.

        Returns a :class:`Reading`: check ``reading.valid``; when false,
        ``reading.reason`` says why (a normal outcome, not an exception).
        ``max_age_ms`` (> 0) overrides the service's ``publish.max_reading_age_ms``: an
        older reading comes back with reason ``stale``, or raises :class:`StaleReading`
        when ``raise_stale`` is true.
        """
        request: Json = {"cmd": "distance"}
        if max_age_ms is not None:
            request["max_age_ms"] = max_age_ms
        reply = self.request(request)
        reading = Reading.from_json(reply.get("reading"))
        if raise_stale and reading.stale:
            raise StaleReading(reading)
        return reading

    def status(self) -> Json:
        """The service's status object (docs/protocol.md, ``status``): source, cameras,
        pipeline timings, calibration, clients and the current ``reading`` (a dict)."""
        reply = self.request({"cmd": "status"})
        status = reply.get("status")
        if not isinstance(status, dict):
            raise ProtocolError("malformed", "status reply without a status object", reply)
        return status

    def zones_report(self) -> Json:
        """The whole ``zones`` reply: ``frame``, ``stamp_ns``, ``age_ms``, ``zones``,
        ``camera_pose`` and (when calibrated) ``camera``."""
        reply = self.request({"cmd": "zones"})
        if not isinstance(reply.get("zones"), list):
            raise ProtocolError("malformed", "zones reply without a zones list", reply)
        return {k: v for k, v in reply.items() if k != "ok"}

    def zones(self) -> List[Json]:
        """The keep-out zones of the latest frame, one dict per zone (``name``,
        ``state`` ``occupied``/``clear``/``unknown``, ``reason``, ``points``,
        ``nearest_m``, ``nearest_point_m``, ``visible_fraction``); empty when none are
        configured."""
        return list(self.zones_report()["zones"])

    def calibration(self) -> Json:
        """The calibration in force: ``calibrated`` and, from a file, ``path`` and ``text``."""
        reply = self.request({"cmd": "calibration"})
        return {k: v for k, v in reply.items() if k != "ok"}

    def reload(self) -> Json:
        """Re-reads the service's configuration file: ``changed`` and ``restart_needed``
        (lists of keys). :class:`ProtocolError` ``invalid_config`` when it is refused."""
        reply = self.request({"cmd": "reload"})
        return {k: v for k, v in reply.items() if k != "ok"}

    def snapshot_items(self) -> List[str]:
        """The snapshot items the service offers (``hello``'s ``snapshot_items``)."""
        if self._connection is None or self._connection.hello is None:
            self.hello()
        assert self._connection is not None and self._connection.hello is not None
        return list(self._connection.hello.get("snapshot_items") or [])

    def snapshot(self, items: Optional[Iterable[str]] = None) -> Snapshot:
        """The latest result as numpy arrays (see :class:`Snapshot`).

        ``items`` chooses what to fetch (default :data:`DEFAULT_SNAPSHOT_ITEMS`); items
        the service does not offer are left out, so the snapshot may lack some (check
        with ``"confidence" in snap``). ``ValueError`` when none of them is offered;
        :class:`ProtocolError` ``not_available`` before the first frame.
        """
        wanted = list(DEFAULT_SNAPSHOT_ITEMS if items is None else items)
        if isinstance(items, str):
            wanted = [items]
        offered = set(self.snapshot_items())
        chosen = [item for item in wanted if item in offered]
        if not chosen:
            raise ValueError(f"the service offers none of {wanted} (it offers {sorted(offered)})")
        reply, connection = self._exchange({"cmd": "snapshot", "items": chosen})
        if reply.get("ok") is not True:
            _check(reply)
        descriptors = reply.get("payloads")
        if not isinstance(descriptors, list):
            self.close()
            raise ProtocolError("malformed", "snapshot reply without payloads", reply)
        try:
            blobs = connection.read_payloads(descriptors, connection.reply_deadline)
        except BaseException:
            self.close()
            raise
        return Snapshot(reply, _decode_all(descriptors, blobs))

    def subscribe(self, kind: str = "readings", max_hz: Optional[float] = None,
                  event_timeout_s: Optional[float] = None,
                  results: Optional[Iterable[str]] = None) -> Iterator[Any]:
        """Events of a stream, on a connection of their own, until the generator is
        closed (``close()``, ``break`` out of a ``for`` loop, or garbage collection).

        ``kind``: ``readings`` yields :class:`Reading` objects (``skipped`` counts the
        readings lost before each one); ``depth`` yields dicts with ``frame``,
        ``stamp_ns``, ``depth_valid``, ``reading`` (a :class:`Reading`), ``skipped``,
        ``depth`` (float32 metres, NaN = none) and ``header`` (the event line);
        ``zones`` yields the event dicts (``frame``, ``stamp_ns``, ``age_ms``,
        ``zones``); ``raw`` yields dicts with ``frame``, ``left_stamp_ns``,
        ``right_stamp_ns``, ``skipped``, ``raw_left``, ``raw_right`` (uint8) and ``header``.
        ``max_hz`` (> 0) lowers the event rate.

        ``results`` (``raw`` only): ``["depth", "cloud"]`` or either (and ``"colour"``,
        the frames' and, with the cloud, the cloud's colour); each raw event then
        also holds that pair's ``depth`` (float32 metres, NaN = none, not rounded to the
        millimetre), ``cloud`` (N x 4 float32) and ``depth_valid``.

        Subscribing happens on the first ``next()``. Waiting for an event is bounded by
        ``event_timeout_s`` (default: none, since a source that went down sends nothing
        more); past it :class:`ServiceUnavailable` is raised. A lost connection raises
        :class:`ServiceUnavailable`.
        """
        request: Json = {"cmd": "subscribe", "stream": kind}
        if max_hz is not None:
            request["max_hz"] = max_hz
        if results is not None:
            request["with"] = list(results)
        connection = _Connection(self.socket_path, self.timeout_s)
        try:
            deadline = connection.deadline()
            connection.send(request)
            _check(connection.read_line(deadline))
            while True:
                event = connection.read_line(
                    None if event_timeout_s is None else connection.deadline(event_timeout_s))
                if "event" not in event:
                    _check(event)  # an error line: raises
                    continue
                descriptors: List[Json] = []
                if isinstance(event.get("payloads"), list):
                    descriptors = event["payloads"]
                elif event.get("bytes") is not None:
                    descriptors = [{"name": "depth" if event["event"] == "depth" else "payload",
                                    "format": event.get("format"), "width": event.get("width"),
                                    "height": event.get("height"), "bytes": event["bytes"]}]
                # The event's payloads follow its line: within the client's timeout.
                arrays = _decode_all(descriptors,
                                     connection.read_payloads(descriptors, connection.deadline()))
                yield _event_object(event, arrays)
        finally:
            connection.close()


def _event_object(event: Json, arrays: Dict[str, np.ndarray]) -> Any:
    kind = event.get("event")
    skipped = int(event.get("skipped") or 0)
    if kind == "reading":
        return Reading.from_json(event.get("reading"), skipped=skipped)
    out: Json = {k: v for k, v in event.items() if k not in ("event", "payloads", "bytes")}
    out["skipped"] = skipped
    out["header"] = event
    if isinstance(event.get("reading"), dict):
        out["reading"] = Reading.from_json(event["reading"])
    out.update(arrays)
    return out
