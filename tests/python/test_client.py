"""The Python client against a real stereod replaying Middlebury tsukuba (conftest.py).

The recording repeats one pair, so every frame's result is the same and a snapshot taken
by `stereoctl` can be compared with one taken by the client."""

import os
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest

from conftest import BASELINE_M, FOCAL_PX, SIZE, SOURCE_DIR
from image_files import read_pfm, read_png, read_png_gray
from stereod import (Client, ProtocolError, Reading, ServiceUnavailable, Snapshot,
                     StaleReading)

WIDTH, HEIGHT = SIZE
FB = FOCAL_PX * BASELINE_M


def test_hello(client):
    hello = client.hello()
    assert hello["service"] == "stereod"
    assert hello["protocol"] == 1
    assert hello["calibrated"] is True
    for command in ("hello", "distance", "status", "snapshot", "subscribe", "zones"):
        assert command in hello["commands"]
    assert {"readings", "depth", "zones"} <= set(hello["streams"])
    assert {"depth", "disparity", "left", "cloud"} <= set(hello["snapshot_items"])


def test_distance_is_a_valid_reading(client):
    reading = client.distance()
    assert isinstance(reading, Reading)
    assert reading.valid, reading
    assert reading.reason is None and reading.message is None
    # tsukuba's nearest objects in the centre lie at disparities of about 10..14 px.
    assert FB / 16 < reading.distance_m < FB / 9
    assert reading.stamp_ns > 0
    assert reading.age_ms >= 0
    assert reading.frame >= 0
    assert 0.5 < reading.valid_fraction <= 1.0
    assert 0.0 <= reading.in_range_fraction <= 1.0
    assert reading.region_pixels > 0
    assert reading.producing and not reading.stale
    assert reading.calibration_suspect is False
    assert reading.raw["distance_m"] == reading.distance_m
    # The default region, a quarter in, sees that near in every column.
    assert reading.out_of_view_fraction is None


def test_a_reading_says_how_much_of_its_region_cannot_see_that_near():
    # A region from the image's left edge: its first columns hold no match in the right
    # image as near as the distance; the reading keeps its number and says how much.
    raw = {"valid": True, "distance_m": 0.8, "frame": 3, "valid_fraction": 0.9,
           "out_of_view_fraction": 0.125}
    reading = Reading.from_json(raw)
    assert reading.valid and reading.distance_m == 0.8
    assert reading.out_of_view_fraction == 0.125


def test_distance_older_than_allowed_is_stale_not_an_exception(client):
    # Processing alone takes longer than a microsecond: every reading is older.
    reading = client.distance(max_age_ms=0.001)
    assert reading.valid is False
    assert reading.distance_m is None
    assert reading.reason == "stale"
    assert reading.message
    assert reading.stale and not reading.producing
    assert reading.age_ms > 0.001  # the stale reading still says how old it is
    assert reading.frame >= 0

    with pytest.raises(StaleReading) as raised:
        client.distance(max_age_ms=0.001, raise_stale=True)
    assert raised.value.reading.reason == "stale"
    # A fresh-enough reading does not raise.
    assert client.distance(max_age_ms=60_000, raise_stale=True).valid


def test_status(client):
    status = client.status()
    assert status["state"] == "running"
    assert status["source"]["kind"] == "replay"
    assert isinstance(status["source"]["cameras"], list)
    assert status["pipeline"]["frames"] > 0
    assert "match" in status["pipeline"]["stage_ms"]
    assert status["calibration"]["kind"] == "rectified"
    assert status["calibration"]["focal_px"] == pytest.approx(FOCAL_PX)
    assert status["calibration"]["baseline_m"] == pytest.approx(BASELINE_M)
    assert status["clients"]["connected"] >= 1
    assert Reading.from_json(status["reading"]).valid


def test_zones_none_configured(client):
    assert client.zones() == []
    report = client.zones_report()
    assert report["zones"] == []
    assert report["frame"] >= 0
    assert report["camera"]["width"] == WIDTH and report["camera"]["height"] == HEIGHT


def test_calibration(client):
    calibration = client.calibration()
    assert calibration["calibrated"] is True
    assert calibration["path"].endswith("calib.yaml")
    assert calibration["text"]


def test_snapshot_arrays(client):
    snap = client.snapshot(("depth", "disparity", "left", "cloud"))
    assert isinstance(snap, Snapshot)
    assert set(snap) == {"depth", "disparity", "left", "cloud"}
    assert snap.frame >= 0 and snap.stamp_ns > 0
    assert snap.depth_valid is True
    assert snap.reading.valid
    assert snap.calibration["focal_px"] == pytest.approx(FOCAL_PX)

    depth, disparity, left, cloud = snap["depth"], snap["disparity"], snap["left"], snap["cloud"]
    assert depth.dtype == np.float32 and depth.shape == (HEIGHT, WIDTH)
    assert disparity.dtype == np.float32 and disparity.shape == (HEIGHT, WIDTH)
    assert left.dtype == np.uint8 and left.shape == (HEIGHT, WIDTH)
    assert cloud.dtype == np.float32 and cloud.ndim == 2 and cloud.shape[1] == 4

    known = np.isfinite(depth)
    assert known.sum() > depth.size // 2
    assert np.all(depth[known] > 0)
    # The outputs leave out depths beyond their cap (output.max_depth_m; here the default,
    # f*B / 4 px = 2.5 m).
    cap_m = client.status()["pipeline"]["max_output_depth_m"]
    assert cap_m == pytest.approx(FB / 4)
    assert np.all(depth[known] <= cap_m)
    # NaN only where there is no depth: never where the disparity gives a depth in range
    # (above the payload's millimetre floor, within the cap).
    in_range = np.isfinite(disparity) & (disparity > FB / 65.535) & (disparity >= FB / cap_m * 1.0001)
    assert not np.any(np.isnan(depth) & in_range)
    # Depth and disparity of one frame agree: Z = f*B/d, to the millimetre.
    both = known & np.isfinite(disparity) & (disparity > 0)
    np.testing.assert_allclose(depth[both], FB / disparity[both], atol=0.0011)
    # The cloud: one point per pixel with depth, in front of the camera.
    assert cloud.shape[0] > 0
    assert np.all(cloud[:, 2] > 0)
    assert np.all((cloud[:, 3] >= 0) & (cloud[:, 3] <= 255))
    assert cloud[:, 2].min() == pytest.approx(np.nanmin(depth), abs=0.0011)


def test_snapshot_matches_stereoctl_files(service, client, ctl, tmp_path):
    depth_png, disparity_pfm, left_png = (tmp_path / "d.png", tmp_path / "d.pfm",
                                          tmp_path / "l.png")
    run = ctl(service, "snapshot", "--depth", str(depth_png), "--disparity",
              str(disparity_pfm), "--left", str(left_png))
    assert run.returncode == 0, run.stderr
    snap = client.snapshot(("depth", "disparity", "left", "left_colour"))

    depth_mm = read_png_gray(depth_png)
    assert depth_mm.dtype == np.uint16 and depth_mm.shape == (HEIGHT, WIDTH)
    np.testing.assert_array_equal(np.isnan(snap["depth"]), depth_mm == 0)
    known = depth_mm > 0
    np.testing.assert_allclose(snap["depth"][known], depth_mm[known] / 1000.0, atol=0.001)

    disparity = read_pfm(disparity_pfm)
    assert disparity.shape == (HEIGHT, WIDTH)
    np.testing.assert_array_equal(np.isinf(snap["disparity"]), np.isinf(disparity))
    finite = np.isfinite(disparity)
    np.testing.assert_allclose(snap["disparity"][finite], disparity[finite], atol=1e-4)

    # The recording's left images are colour: stereoctl writes the left in colour.
    np.testing.assert_array_equal(snap["left_colour"], read_png(left_png))


def test_colour_of_a_colour_recording(client):
    snap = client.snapshot(("left", "left_colour", "cloud", "cloud_colour"))
    colour = snap["left_colour"]
    assert colour.dtype == np.uint8 and colour.shape == (HEIGHT, WIDTH, 3)
    # Red first: its BT.601 grey is the grey the matcher saw, within rounding.
    grey = colour[..., 0] * 0.299 + colour[..., 1] * 0.587 + colour[..., 2] * 0.114
    assert np.abs(grey - snap["left"].astype(np.float64)).mean() < 1.0
    # A colour scene, not grey in three channels.
    assert np.abs(colour[..., 0].astype(int) - colour[..., 2].astype(int)).mean() > 5
    assert snap["cloud_colour"].shape == (snap["cloud"].shape[0], 3)
    assert snap["cloud_colour"].dtype == np.uint8


def test_snapshot_asks_only_for_offered_items(client):
    offered = client.hello()["snapshot_items"]
    snap = client.snapshot(("depth", "confidence"))
    assert ("confidence" in snap) == ("confidence" in offered)
    if "confidence" in snap:
        assert snap["confidence"].dtype == np.uint8
        assert snap["confidence"].shape == (HEIGHT, WIDTH)
    default = client.snapshot()
    assert {"depth", "disparity", "left", "cloud"} <= set(default)
    with pytest.raises(ValueError):
        client.snapshot(("no_such_item",))


def test_subscribe_readings_yields_increasing_frames(client):
    stream = client.subscribe("readings", event_timeout_s=30)
    frames = []
    for reading in stream:
        assert isinstance(reading, Reading)
        assert reading.valid, reading
        frames.append(reading.frame)
        if len(frames) == 3:
            break
    stream.close()
    assert frames == sorted(frames) and len(set(frames)) == 3
    # The client stays usable for requests during and after a subscription.
    assert client.distance().valid


def test_subscribe_depth_frames(client):
    stream = client.subscribe("depth", max_hz=5, event_timeout_s=30)
    events = [next(stream), next(stream)]
    stream.close()
    assert events[0]["frame"] < events[1]["frame"]
    for event in events:
        assert event["depth"].dtype == np.float32
        assert event["depth"].shape == (HEIGHT, WIDTH)
        assert event["depth_valid"] is True
        assert event["reading"].valid
        assert event["stamp_ns"] > 0
        assert event["skipped"] >= 0
        assert event["header"]["format"] == "u16_mm"
    np.testing.assert_array_equal(np.isnan(events[0]["depth"]), np.isnan(events[1]["depth"]))


def test_subscribe_raw_with_depth_and_cloud(client):
    stream = client.subscribe("raw", event_timeout_s=30, results=["depth", "cloud"])
    event = next(stream)
    stream.close()
    assert event["raw_left"].dtype == np.uint8
    assert event["raw_left"].shape == (HEIGHT, WIDTH)
    assert event["depth_valid"] is True
    # The pair's own depth in metres, NaN where there is none, and its cloud.
    depth = event["depth"]
    assert depth.dtype == np.float32
    assert depth.shape == (HEIGHT, WIDTH)
    assert np.isnan(depth).any() and (depth[~np.isnan(depth)] > 0).all()
    cloud = event["cloud"]
    assert cloud.dtype == np.float32 and cloud.shape[1] == 4
    assert 0 < cloud.shape[0] <= np.count_nonzero(~np.isnan(depth))
    with pytest.raises(ProtocolError) as raised:
        next(client.subscribe("raw", results=["mesh"]))
    assert raised.value.code == "bad_request"


def test_subscribe_zones(client):
    stream = client.subscribe("zones", event_timeout_s=30)
    event = next(stream)
    stream.close()
    assert event["zones"] == []
    assert event["frame"] >= 0


def test_unknown_command_is_a_protocol_error(client):
    with pytest.raises(ProtocolError) as raised:
        client.request({"cmd": "frobnicate"})
    assert raised.value.code == "unknown_command"
    assert "distance" in raised.value.message  # it lists the known commands
    # The connection stays usable.
    assert client.distance().valid


def test_bad_argument_is_a_protocol_error(client):
    with pytest.raises(ProtocolError) as raised:
        client.distance(max_age_ms=-1)
    assert raised.value.code == "bad_request"
    with pytest.raises(ProtocolError) as raised:
        next(client.subscribe("no_such_stream"))
    assert raised.value.code == "bad_request"


def test_no_service_is_service_unavailable(tmp_path):
    with Client(str(tmp_path / "missing.sock"), timeout_s=1.0) as client:
        with pytest.raises(ServiceUnavailable):
            client.distance()
        with pytest.raises(ServiceUnavailable):
            client.hello()
    # A socket file nobody listens on: connection refused.
    path = str(tmp_path / "dead.sock")
    dead = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    dead.bind(path)
    dead.close()
    with pytest.raises(ServiceUnavailable):
        Client(path, timeout_s=1.0).status()
    with pytest.raises(ServiceUnavailable):
        next(Client(path, timeout_s=1.0).subscribe("readings"))


def _fake_service(path, answer: bytes):
    """A one-connection server that reads one line and answers `answer`, then closes."""
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(path)
    server.listen(1)

    def serve():
        connection, _ = server.accept()
        with connection:
            connection.makefile("rb").readline()
            connection.sendall(answer)
        server.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize("answer,error", [
    (b"this is not json\n", ProtocolError),
    (b"[1, 2]\n", ProtocolError),
    (b'{"no_ok": 1}\n', ProtocolError),
    (b'{"ok": true, "reading": {"distance_m": 1}}\n', ProtocolError),
    (b"", ServiceUnavailable),                       # closed without a reply
    (b'{"ok": true, "reading"', ServiceUnavailable),  # closed in the middle of a line
])
def test_malformed_or_cut_replies(tmp_path, answer, error):
    path = str(tmp_path / "fake.sock")
    thread = _fake_service(path, answer)
    with pytest.raises(error) as raised:
        Client(path, timeout_s=5.0).distance()
    if error is ProtocolError:
        assert raised.value.code == "malformed"
    thread.join(5)


def test_a_suspect_calibration_is_exposed_and_printed(tmp_path):
    path = str(tmp_path / "fake.sock")
    answer = (b'{"ok":true,"reading":{"valid":true,"distance_m":0.278,"stamp_ns":5,'
              b'"stamp_realtime_ns":1764000000000000005,"age_ms":12.4,"frame":3,'
              b'"calibration_suspect":true,"calibration_row_offset_px":1.523}}\n')
    thread = _fake_service(path, answer)
    reading = Client(path, timeout_s=5.0).distance()
    thread.join(5)
    assert reading.valid and reading.distance_m == 0.278
    assert reading.calibration_suspect is True
    assert reading.calibration_row_offset_px == 1.523
    assert reading.stamp_realtime_ns == 1764000000000000005
    # The example says so after the distance.
    os.unlink(path)
    thread = _fake_service(path, answer)
    env = dict(os.environ, PYTHONPATH=str(SOURCE_DIR / "python"))
    run = subprocess.run(
        [sys.executable, str(SOURCE_DIR / "python" / "examples" / "nearest.py"),
         "--socket", path, "--count", "1"],
        capture_output=True, text=True, timeout=60, env=env)
    thread.join(5)
    assert run.returncode == 0, run.stderr
    assert run.stdout == "frame 3  0.278 m  age 12 ms  CALIBRATION SUSPECT: rows +1.52 px apart\n"


def test_payload_cut_short_is_service_unavailable(tmp_path):
    path = str(tmp_path / "fake.sock")
    header = (b'{"ok":true,"frame":1,"payloads":[{"name":"depth","format":"u16_mm",'
              b'"width":4,"height":2,"bytes":16}]}\n')
    _fake_service(path, b'{"ok":true,"snapshot_items":["depth"]}\n')
    client = Client(path, timeout_s=5.0)
    assert client.snapshot_items() == ["depth"]
    # The fake closed after hello: the snapshot reconnects to a second fake, which cuts
    # the payload short.
    os.unlink(path)
    _fake_service(path, header + b"\x01\x00" * 3)
    with pytest.raises(ServiceUnavailable):
        client.snapshot(("depth",))


def test_example_prints_a_distance(service):
    env = dict(os.environ, PYTHONPATH=str(SOURCE_DIR / "python"))
    run = subprocess.run(
        [sys.executable, str(SOURCE_DIR / "python" / "examples" / "nearest.py"),
         "--socket", service.socket, "--count", "2"],
        capture_output=True, text=True, timeout=60, env=env)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert len(lines) == 2
    assert all(" m  age " in line for line in lines), run.stdout
    stale = subprocess.run(
        [sys.executable, str(SOURCE_DIR / "python" / "examples" / "nearest.py"),
         "--socket", service.socket, "--count", "1", "--max-age-ms", "0.001"],
        capture_output=True, text=True, timeout=60, env=env)
    assert stale.returncode == 0 and stale.stdout.startswith("no reading: stale"), stale.stdout
    missing = subprocess.run(
        [sys.executable, str(SOURCE_DIR / "python" / "examples" / "nearest.py"),
         "--socket", service.socket + ".missing", "--count", "1"],
        capture_output=True, text=True, timeout=60, env=env)
    assert missing.returncode == 0 and missing.stdout.startswith("service unavailable"), missing.stdout


def test_lost_service_raises_then_the_client_reconnects(own_service):
    client = Client(own_service.socket, timeout_s=10.0)
    stream = client.subscribe("readings", event_timeout_s=30)
    assert next(stream).valid
    assert client.distance().valid
    own_service.stop()
    with pytest.raises(ServiceUnavailable):
        client.distance()
    with pytest.raises(ServiceUnavailable):
        for _ in stream:  # events already sent may come first; then the loss
            pass
    own_service.start()
    own_service.wait_until_producing()
    assert client.distance().valid  # the same client, a new connection
    client.close()
