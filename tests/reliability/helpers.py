"""Shared helpers of the reliability suite: raw multipart bodies, store snapshots, real server processes."""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

BOUNDARY = "reliability-boundary-7f3a"
# test-fast describe settings for every real process (a cheap spectrum, ~300 vertices)
FAST_ENV = {
    "SHAPEBAG_DESCRIBE__K": "40",
    "SHAPEBAG_DESCRIBE__M": "20",
    "SHAPEBAG_DESCRIBE__TARGET_VERTICES": "300",
    "SHAPEBAG_POLL_INTERVAL_S": "0.1",
    "SHAPEBAG_DEFAULT_VOCABULARY": "",
    "SHAPEBAG_VOCABULARY_SIZE": "16",
    "SHAPEBAG_AUTO_VOCABULARY_MIN_MODELS": "1000000",
    "SHAPEBAG_LOG_LEVEL": "WARNING",
    "SHAPEBAG_WARM_UP": "false",
}


def multipart(filename: str, content: bytes, fields: dict[str, str | bytes] | None = None) -> bytes:
    """A multipart/form-data body built by hand, so that names and values can hold any bytes."""
    out = []
    for name, value in (fields or {}).items():
        raw = value if isinstance(value, bytes) else value.encode("utf-8")
        out.append(
            f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n'.encode() + raw + b"\r\n"
        )
    fname = filename.encode("utf-8").replace(b'"', b"%22")
    out.append(
        f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="file"; filename="'.encode()
        + fname
        + b'"\r\nContent-Type: application/octet-stream\r\n\r\n'
        + content
        + b"\r\n"
    )
    out.append(f"--{BOUNDARY}--\r\n".encode())
    return b"".join(out)


MULTIPART_HEADERS = {"content-type": f"multipart/form-data; boundary={BOUNDARY}"}


@dataclass(frozen=True)
class StoreSnapshot:
    """What must not change when a request is refused."""

    models: list[tuple]
    jobs: int
    vectors: int
    vocabularies: int
    files: dict[str, str] = field(default_factory=dict)  # relative path -> sha256 (db files excluded)


def snapshot(data_dir: Path) -> StoreSnapshot:
    conn = sqlite3.connect(f"file:{data_dir / 'shapebag.db'}?mode=ro", uri=True)
    try:
        models = conn.execute("SELECT id, name, label, sha256, status FROM models ORDER BY id").fetchall()
        jobs = conn.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
        vectors = conn.execute("SELECT COUNT(*) FROM bof").fetchone()[0]
        vocabularies = conn.execute("SELECT COUNT(*) FROM vocabularies").fetchone()[0]
    finally:
        conn.close()
    files = {}
    for p in sorted(data_dir.rglob("*")):
        rel = str(p.relative_to(data_dir))
        if p.is_file() and not rel.startswith("shapebag.db") and "thumbnails" not in rel:
            files[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return StoreSnapshot(models, jobs, vectors, vocabularies, files)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Proc:
    """A `shapebag` subprocess in its own session (so kill -9 reaches it and nothing else)."""

    def __init__(self, args: list[str], env: dict[str, str], log: Path) -> None:
        self.log_path = log
        self._log = open(log, "ab")  # noqa: SIM115 - outlives this call (the child writes to it)
        self.popen = subprocess.Popen(
            [sys.executable, "-m", "app.cli", *args],
            env=env,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            cwd=Path(__file__).resolve().parents[2],
        )

    @property
    def pid(self) -> int:
        return self.popen.pid

    def kill9(self) -> None:
        """SIGKILL the whole process group (the server and its worker/pool children)."""
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.wait(10)

    def stop(self, timeout_s: float = 20.0) -> None:
        if self.popen.poll() is None:
            os.killpg(self.popen.pid, signal.SIGTERM)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.kill9()
        self._log.close()

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")[-4000:]


def env_for(data_dir: Path, **extra: str) -> dict[str, str]:
    env = dict(
        os.environ,
        **FAST_ENV,
        SHAPEBAG_DATA_DIR=str(data_dir),
        SHAPEBAG_ADMIN_TOKEN="reliability-secret-kkkkkkkkkkkkk",
    )
    env.update({k: str(v) for k, v in extra.items()})
    return env


def refused_start(env: dict[str, str]) -> tuple[int, list[str]]:
    """Run `shapebag serve` where it must refuse to start: (exit code, stderr lines), less the CLI's
    informational "data directory: ..." line (it says which directory it resolved)."""
    p = subprocess.run(
        [sys.executable, "-m", "app.cli", "serve", "--port", "1"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = [ln for ln in p.stderr.strip().splitlines() if not ln.startswith("data directory: ")]
    return p.returncode, lines


def start_server(data_dir: Path, log: Path, **extra: str) -> tuple[Proc, str]:
    port = free_port()
    proc = Proc(["serve", "--port", str(port)], env_for(data_dir, **extra), log)
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.popen.poll() is not None:
            raise AssertionError(f"server exited with {proc.popen.returncode}:\n{proc.log()}")
        try:
            if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                return proc, base
        except httpx.TransportError:
            pass
        time.sleep(0.3)
    proc.kill9()
    raise AssertionError(f"server did not come up:\n{proc.log()}")


def descendants(pid: int) -> set[int]:
    """Live (non-zombie) descendant pids of `pid`, from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        rest = stat[stat.rfind(")") + 2 :].split()
        state, ppid = rest[0], int(rest[1])
        if state != "Z":
            children.setdefault(ppid, []).append(int(entry.name))
    out: set[int] = set()
    todo = [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out
