"""Fixtures of the Python client's tests: a real stereod replaying a recording of the
Middlebury tsukuba pair, with a rectified-only calibration.

STEREOD_BUILD_DIR names the build tree (daemon/stereod, ctl/stereoctl; default
/work/main/build); STEREOD_SHARED_DATA_DIR the shared data (default: ../shared/data
beside the source tree).
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

SOURCE_DIR = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(SOURCE_DIR / "python"))

from stereod import Client, ServiceUnavailable  # noqa: E402

BUILD_DIR = Path(os.environ.get("STEREOD_BUILD_DIR", "/work/main/build"))
DATA_DIR = Path(os.environ.get("STEREOD_SHARED_DATA_DIR", str(SOURCE_DIR.parent / "shared" / "data")))
STEREOD = BUILD_DIR / "daemon" / "stereod"
STEREOCTL = BUILD_DIR / "ctl" / "stereoctl"
TSUKUBA = DATA_DIR / "middlebury" / "tsukuba"
SIZE = (384, 288)
FOCAL_PX = 100.0
BASELINE_M = 0.1
PAIRS = 4
START_LIMIT_S = 60.0


def _make_recording(directory: Path) -> Path:
    recording = directory / "rec"
    (recording / "left").mkdir(parents=True)
    (recording / "right").mkdir()
    rows = ["index,left_stamp_ns,right_stamp_ns,left,right"]
    for i in range(PAIRS):
        name = f"{i:06d}.png"
        os.symlink(TSUKUBA / "im3.png", recording / "left" / name)
        os.symlink(TSUKUBA / "im4.png", recording / "right" / name)
        stamp = i * 100_000_000
        rows.append(f"{i},{stamp},{stamp},left/{name},right/{name}")
    (recording / "frames.csv").write_text("\n".join(rows) + "\n")
    return recording


class Service:
    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.recording = _make_recording(directory)
        self.calibration = directory / "calib.yaml"
        subprocess.run(
            [str(STEREOCTL), "calibrate", "--rectified", "--focal-px", str(FOCAL_PX),
             "--baseline-m", str(BASELINE_M), "--size", f"{SIZE[0]}x{SIZE[1]}",
             "--out", str(self.calibration)],
            check=True, capture_output=True)
        self.socket = str(directory / "s.sock")
        self.log_path = directory / "stereod.log"
        self.start()

    def start(self) -> None:
        self._log = open(self.log_path, "ab")
        self.process = subprocess.Popen(
            [str(STEREOD), "--replay", str(self.recording), "--calib", str(self.calibration),
             "--socket", self.socket],
            stdout=self._log, stderr=subprocess.STDOUT)

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def wait_until_producing(self) -> None:
        deadline = time.monotonic() + START_LIMIT_S
        problem = ""
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"stereod exited ({self.process.returncode}):\n{self.log()}")
            try:
                with Client(self.socket, timeout_s=2.0) as client:
                    reading = client.distance()
                if reading.reason != "no_frame_yet":
                    return
                problem = "no frame yet"
            except ServiceUnavailable as error:
                problem = str(error)
            time.sleep(0.02)
        raise RuntimeError(f"stereod never produced a reading: {problem}\n{self.log()}")

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._log.close()


def _check_inputs() -> None:
    for path in (STEREOD, STEREOCTL):
        if not path.is_file():
            pytest.fail(f"{path} not built (set STEREOD_BUILD_DIR to the build tree)")
    if not (TSUKUBA / "im3.png").is_file():
        pytest.fail(f"{TSUKUBA} missing (set STEREOD_SHARED_DATA_DIR)")


@pytest.fixture(scope="session")
def service(tmp_path_factory):
    _check_inputs()
    running = Service(tmp_path_factory.mktemp("stereod"))
    try:
        running.wait_until_producing()
        yield running
    finally:
        running.stop()


@pytest.fixture
def own_service(tmp_path):
    """A service of the test's own, which it may stop and start."""
    _check_inputs()
    running = Service(tmp_path)
    try:
        running.wait_until_producing()
        yield running
    finally:
        running.stop()


@pytest.fixture
def client(service):
    with Client(service.socket, timeout_s=10.0) as connected:
        yield connected


def stereoctl(service, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(STEREOCTL), *args, "--socket", service.socket],
                          capture_output=True, text=True, timeout=60)


@pytest.fixture
def ctl():
    return stereoctl


def pytest_report_header(config):
    return f"stereod build: {BUILD_DIR}; data: {DATA_DIR}"


