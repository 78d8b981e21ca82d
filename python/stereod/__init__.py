"""Python client of the stereod stereo depth service.

The service speaks newline-delimited JSON on a Unix socket (docs/protocol.md, protocol
version 1). This package wraps it::

    from stereod import Client

    with Client() as client:
        reading = client.distance()
        if reading.valid:
            print(f"{reading.distance_m:.3f} m")
        else:
            print("no reading:", reading.reason, reading.message)

A missing distance is a normal outcome and comes back as a :class:`Reading` whose
``valid`` is false; exceptions mean the service cannot be reached
(:class:`ServiceUnavailable`) or answered something this client cannot use
(:class:`ProtocolError`).
"""

from .client import (
    DEFAULT_SNAPSHOT_ITEMS,
    DEFAULT_SOCKET_PATH,
    MAX_PAYLOAD_BYTES,
    Client,
    ProtocolError,
    Reading,
    ServiceUnavailable,
    Snapshot,
    StaleReading,
    StereodError,
    decode_payload,
)

__all__ = [
    "DEFAULT_SNAPSHOT_ITEMS",
    "DEFAULT_SOCKET_PATH",
    "MAX_PAYLOAD_BYTES",
    "Client",
    "ProtocolError",
    "Reading",
    "ServiceUnavailable",
    "Snapshot",
    "StaleReading",
    "StereodError",
    "decode_payload",
]

__version__ = "0.1.0"
