"""Where a result came from: the code (git commit and whether the code differed from it), the
checkpoints that played, and the machine.

Every result file the tools write (evaluation, suites, sweeps, learning curves, the benchmark)
records :func:`provenance`, so a reader can tell whether a shipped result was made with the
shipped checkpoint and the committed code (``tests/tools/test_shipped_results.py`` checks it)::

    {"code": {"commit": "3f2c...", "dirty": false}, "env": {"rules": 1},
     "checkpoints": {"gcn": {"path": "agents/checkpoints/gcn_default.pt", "sha256": "9a1e..."}},
     "machine": {"cpu": "AMD EPYC ...", "cores": 2, "python": "3.11.7", "platform": "Linux-..."},
     "controllers": {"mine.py:Ctrl": {"target": "mine.py:Ctrl", "file": "/home/.../mine.py",
                                      "sha256": "77b0..."}}}

``controllers`` is there only where an agent is named by an import path (the file its class is
in) or by a policy file of another library (that file), so that the run's controllers can be
rebuilt from another folder; a controller evaluated as an object in memory is recorded as
``{"in_memory": "module.Class"}``, which nothing rebuilds.

``dirty`` is true when a file of the code (anything tracked or untracked outside ``docs/``, the
folder results are written to) differs from the commit; ``commit`` is null outside a git
checkout (an installed wheel).
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import subprocess
from pathlib import Path
from typing import Any, Iterable

from agents.common.specs import checkpoint_files

__all__ = ["PNG_KEY", "REPO_ROOT", "code_version", "describe", "file_sha256", "machine",
           "png_metadata", "provenance", "read_png_metadata"]

#: The checkout (or installed tree) the code runs from.
REPO_ROOT = Path(__file__).resolve().parents[2]
#: Folders whose changes do not make the code dirty: where results are written.
RESULT_FOLDERS = ("docs",)
#: The key under which PNG figures carry the provenance (a tEXt chunk, JSON).
PNG_KEY = "marl_vertiport provenance"


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(REPO_ROOT), *args], capture_output=True,
                             text=True, timeout=30, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return out.stdout if out.returncode == 0 else None


def code_version() -> dict[str, Any]:
    """``{"commit": HEAD or None, "dirty": bool or None}`` of the code this process runs."""
    if not (REPO_ROOT / ".git").exists():
        return {"commit": None, "dirty": None}
    head = _git("rev-parse", "HEAD")
    excluded = [f":(exclude){folder}" for folder in RESULT_FOLDERS]
    status = _git("status", "--porcelain", "--untracked-files=normal", "--", ".", *excluded)
    return {"commit": head.strip() if head else None,
            "dirty": None if status is None else bool(status.strip())}


def _shown(path: Path) -> str:
    """``path`` relative to the checkout when it lies in it, else as given."""
    try:
        return path.resolve().relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return str(path)


@functools.lru_cache(maxsize=1)
def machine() -> dict[str, Any]:
    """The CPU model, core count, vector instructions (AVX2, AVX-512), Python and platform of
    this machine."""
    cpu, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
            elif line.startswith("flags"):
                flags = set(line.split(":", 1)[1].split())
            if cpu and flags:
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(),
            # The vector instructions decide which float kernels numpy and torch pick.
            "vector_instructions": [f for f in ("avx2", "avx512f") if f in flags],
            "python": platform.python_version(), "platform": platform.platform()}


def controller_files(agents: Iterable[str]) -> dict[str, dict[str, str]]:
    """Per agent named by an import path (``module:Class``, ``path/to/file.py:Class``, with
    arguments or not), the absolute path and SHA-256 of the file its class is in (of a policy
    file of another library, ``model.zip`` or ``policy.pt2``, that file): what rebuilds
    the controller from another folder (``marl-vertiport worst-day``) and tells whether the file
    changed since."""
    from agents.common.imports import target_file
    from agents.common.specs import AgentSpecError, foreign_kind, split_spec

    out: dict[str, dict[str, str]] = {}
    for spec in agents:
        try:
            target, _ = split_spec(spec)
        except AgentSpecError:
            continue
        if ":" in target:
            path = target_file(target)
        elif foreign_kind(target) in ("sb3", "exported") and Path(target).is_file():
            path = Path(target).resolve()  # a policy file of another library
        else:
            path = None
        if path is not None:
            out[spec] = {"target": target, "file": str(path), "sha256": file_sha256(path)}
    return out


def provenance(agents: Iterable[str] = ()) -> dict[str, Any]:
    """The record of module docstring for a result that ``agents`` played: per agent that
    plays checkpoints, each file's path and SHA-256 (a list for an ensemble); per agent named
    by an import path, its file (:func:`controller_files`)."""
    agents = list(agents)
    checkpoints: dict[str, Any] = {}
    for spec in agents:
        files = checkpoint_files(spec)
        if not files:
            continue
        entries = [{"path": _shown(f), "sha256": file_sha256(f) if Path(f).is_file() else None}
                   for f in files]
        checkpoints[spec] = entries[0] if len(entries) == 1 else entries
    from marl_vertiport.config import LATEST_RULES

    record = {"code": code_version(), "env": {"rules": LATEST_RULES}, "checkpoints": checkpoints,
              "machine": machine()}
    controllers = controller_files(agents)
    if controllers:
        record["controllers"] = controllers
    return record


def describe(record: dict[str, Any]) -> str:
    """One line for a report: ``code 3f2c1a9 (clean), gcn: gcn_default.pt sha256 9a1e...``."""
    code = record.get("code") or {}
    commit = code.get("commit")
    state = {True: "with uncommitted changes", False: "clean", None: "state unknown"}[code.get("dirty")]
    parts = [f"code {commit[:12]} ({state})" if commit else "code: not a git checkout"]
    for spec, entry in (record.get("checkpoints") or {}).items():
        for e in entry if isinstance(entry, list) else [entry]:
            sha = e.get("sha256") or "missing"
            parts.append(f"{spec}: {Path(e['path']).name} sha256 {sha[:16]}")
    m = record.get("machine") or {}
    if m:
        isa = "/".join(m.get("vector_instructions") or []) or "no AVX2"
        parts.append(f"made on {m.get('cpu')} ({m.get('cores')} cores, {isa})")
    return "; ".join(parts)


def png_metadata(record: dict[str, Any]) -> dict[str, str]:
    """``savefig(metadata=...)`` for a PNG that carries ``record`` as JSON."""
    import json

    return {PNG_KEY: json.dumps(record, sort_keys=True)}


def read_png_metadata(path: str | Path) -> dict[str, Any] | None:
    """The provenance a PNG written with :func:`png_metadata` carries, or None (read from its
    ``tEXt`` chunks; nothing in the file is executed)."""
    import json
    import struct
    import zlib

    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    pos = 8
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"tEXt":
            key, _, text = body.partition(b"\0")
        elif kind == b"zTXt":
            key, _, rest = body.partition(b"\0")
            text = zlib.decompress(rest[1:])
        elif kind == b"iTXt":
            key, _, rest = body.partition(b"\0")
            compressed, rest = rest[0], rest[2:]
            _, _, rest = rest.partition(b"\0")  # language tag
            _, _, text = rest.partition(b"\0")  # translated keyword
            text = zlib.decompress(text) if compressed else text
        else:
            continue
        if key.decode("latin-1") == PNG_KEY:
            return json.loads(text.decode("utf-8"))
    return None
