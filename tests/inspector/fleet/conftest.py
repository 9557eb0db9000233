"""A real Dask cluster on 127.0.0.1 (``dask scheduler`` and two ``dask worker`` processes,
random free ports, one thread each, no dashboard; always torn down) and short simulated drives."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from estimator.sim import simulate

REPO = Path(__file__).resolve().parents[3]
START_TIMEOUT_S = 90.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def dask_env() -> dict[str, str]:
    path = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p)
    return dict(os.environ, PYTHONPATH=path, DASK_DISTRIBUTED__LOGGING__DISTRIBUTED="error")


@dataclass
class DaskCluster:
    address: str
    log_dir: Path
    processes: list[subprocess.Popen[bytes]] = field(default_factory=list)

    def start_worker(self, *, nanny: bool = True) -> subprocess.Popen[bytes]:
        n = len(self.processes)
        cmd = [sys.executable, "-m", "dask", "worker", self.address, "--nthreads", "1",
               "--nworkers", "1", "--host", "127.0.0.1", "--no-dashboard",
               "--death-timeout", "60", "--name", f"test-worker-{n}",
               "--local-directory", str(self.log_dir / f"worker-{n}"),
               "--nanny" if nanny else "--no-nanny"]  # fmt: skip
        proc = subprocess.Popen(
            cmd,
            env=dask_env(),
            stdout=subprocess.DEVNULL,
            stderr=(self.log_dir / f"worker-{n}.log").open("wb"),
        )
        self.processes.append(proc)
        return proc

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout=START_TIMEOUT_S) as client:
            client.wait_for_workers(n, timeout=START_TIMEOUT_S)

    def stop(self) -> None:
        for proc in reversed(self.processes):
            if proc.poll() is None:
                proc.terminate()
        for proc in reversed(self.processes):
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=15)


@pytest.fixture(scope="session")
def dask_cluster(tmp_path_factory) -> Iterator[DaskCluster]:
    log_dir = tmp_path_factory.mktemp("dask")
    port = free_port()
    cluster = DaskCluster(f"tcp://127.0.0.1:{port}", log_dir)
    try:
        cluster.processes.append(
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "dask",
                    "scheduler",
                    "--host",
                    "127.0.0.1",
                    "--port",
                    str(port),
                    "--no-dashboard",
                    "--idle-timeout",
                    "600",
                ],
                env=dask_env(),
                stdout=subprocess.DEVNULL,
                stderr=(log_dir / "scheduler.log").open("wb"),
            )
        )
        _wait_for_port(port, cluster)
        cluster.start_worker()
        cluster.start_worker()
        cluster.wait_for_workers(2)
        yield cluster
    finally:
        cluster.stop()


def _wait_for_port(port: int, cluster: DaskCluster) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        if cluster.processes[0].poll() is not None:
            log = (cluster.log_dir / "scheduler.log").read_text(errors="replace")
            raise RuntimeError(f"dask scheduler exited: {log[-2000:]}")
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 1):
            return
        time.sleep(0.2)
    raise TimeoutError(f"dask scheduler did not listen on {port} in {START_TIMEOUT_S:g} s")


@pytest.fixture(scope="session")
def short_drive(tmp_path_factory) -> tuple[Path, Path]:
    """A 50-second simulated tunnel drive and its route."""
    out = tmp_path_factory.mktemp("drive")
    return simulate("short_tunnel", seed=3, duration_s=50.0).write(out)


def copy_drive(drive: tuple[Path, Path], folder: Path, stem: str) -> Path:
    """The drive as ``<stem>.mcap`` with ``<stem>.route.geojson`` beside it, in ``folder``."""
    log, route = drive
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(log, folder / f"{stem}.mcap")
    shutil.copy(route, folder / f"{stem}.route.geojson")
    return folder / f"{stem}.mcap"
