"""The Python client against a fake service that lies (issue 23): a "valid" reading whose
distance is no number, a payload claiming gigabytes, a reply trickled a byte at a time.
The client must fail closed: an exception of this package, never a valid reading, a
MemoryError or a call held past its timeout."""

import socket
import threading
import time

import pytest

from stereod import MAX_PAYLOAD_BYTES, Client, ProtocolError, ServiceUnavailable


def _fake_service(path, answers, pause_s=0.0):
    """Serves one connection: answers its n-th request line with answers[n], sent
    `pause_s` apart byte by byte when pause_s > 0 (a service that trickles), then closes."""
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(path)
    server.listen(1)
    stop = threading.Event()

    def serve():
        connection, _ = server.accept()
        with connection:
            reader = connection.makefile("rb")
            for answer in answers:
                if not reader.readline():
                    break
                try:
                    if pause_s > 0:
                        for byte in answer:
                            if stop.wait(pause_s):
                                return
                            connection.sendall(bytes([byte]))
                    else:
                        connection.sendall(answer)
                except OSError:
                    return  # the client gave up and closed
        server.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return thread, stop


@pytest.mark.parametrize("distance", [b"NaN", b'"nan"', b"Infinity", b"-Infinity", b"null",
                                      b"-3", b"0", b"true", b'"1.5"'])
def test_a_valid_reading_without_a_distance_is_refused(tmp_path, distance):
    path = str(tmp_path / "fake.sock")
    thread, _ = _fake_service(
        path, [b'{"ok":true,"reading":{"valid":true,"distance_m":' + distance + b'}}\n'])
    with pytest.raises(ProtocolError) as raised:
        Client(path, timeout_s=5.0).distance()
    assert raised.value.code == "malformed"
    thread.join(5)


def test_other_numbers_of_a_reading_must_be_finite_numbers(tmp_path):
    path = str(tmp_path / "fake.sock")
    thread, _ = _fake_service(
        path, [b'{"ok":true,"reading":{"valid":true,"distance_m":1.5,"age_ms":"soon"}}\n'])
    with pytest.raises(ProtocolError):
        Client(path, timeout_s=5.0).distance()
    thread.join(5)
    # A truthful one still reads.
    path = str(tmp_path / "fake2.sock")
    thread, _ = _fake_service(
        path, [b'{"ok":true,"reading":{"valid":true,"distance_m":1.5,"age_ms":12.5,"frame":3}}\n'])
    reading = Client(path, timeout_s=5.0).distance()
    assert reading.valid and reading.distance_m == 1.5 and reading.frame == 3
    thread.join(5)


@pytest.mark.parametrize("claimed", [3 * 10**9, 20 * 10**9, MAX_PAYLOAD_BYTES + 1])
def test_a_payload_claiming_more_than_the_limit_is_refused_unallocated(tmp_path, claimed):
    path = str(tmp_path / "fake.sock")
    header = (b'{"ok":true,"frame":1,"payloads":[{"name":"depth","format":"u16_mm",'
              b'"width":4,"height":2,"bytes":' + str(claimed).encode() + b'}]}\n')
    thread, _ = _fake_service(
        path, [b'{"ok":true,"snapshot_items":["depth"]}\n', header + b"\x01\x00" * 8])
    with pytest.raises(ProtocolError) as raised:  # was: 3 GB allocated; MemoryError at 20 GB
        Client(path, timeout_s=5.0).snapshot(("depth",))
    assert raised.value.code == "malformed"
    assert "MAX_PAYLOAD_BYTES" in raised.value.message
    thread.join(5)


def test_a_payload_cut_short_within_the_limit_allocates_what_came(tmp_path):
    # 512 MiB claimed, 16 bytes sent, then the connection closed: refused as cut short,
    # having held only what arrived.
    path = str(tmp_path / "fake.sock")
    header = (b'{"ok":true,"frame":1,"payloads":[{"name":"depth","format":"u16_mm",'
              b'"width":16384,"height":16384,"bytes":536870912}]}\n')
    thread, _ = _fake_service(
        path, [b'{"ok":true,"snapshot_items":["depth"]}\n', header + b"\x01\x00" * 8])
    with pytest.raises(ServiceUnavailable) as raised:
        Client(path, timeout_s=5.0).snapshot(("depth",))
    assert "16 of 536870912 bytes" in str(raised.value)
    thread.join(5)


def test_a_trickled_reply_ends_at_the_timeout(tmp_path):
    # 42 bytes at one every 0.2 s take 8 s; each byte comes well within the 1 s timeout.
    path = str(tmp_path / "fake.sock")
    _, stop = _fake_service(path, [b'{"ok":true,"reading":{"valid":false,"reason":"x"}}\n'],
                            pause_s=0.2)
    started = time.monotonic()
    try:
        with pytest.raises(ServiceUnavailable):
            Client(path, timeout_s=1.0).distance()
        elapsed = time.monotonic() - started
    finally:
        stop.set()
    assert elapsed < 3.0, f"the call was held {elapsed:.1f} s with a 1 s timeout"
