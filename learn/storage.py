"""Run-directory files written atomically (temporary file in the same folder, then
``os.replace``), and checked loading with clear errors."""

from __future__ import annotations

import csv
import hashlib
import io
import json
from pathlib import Path
from typing import Any

import torch

from finsler.errors import InputError, short
from finsler.infra import files

__all__ = [
    "BEST_FILE",
    "CONFIG_FILE",
    "LATEST_FILE",
    "METRICS_FILE",
    "POLICY_FILE",
    "RESULT_FILE",
    "CorruptFileError",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_run_dir",
    "load_checkpoint",
    "read_json",
    "read_metrics",
    "restore_history",
    "save_checkpoint",
    "write_metrics",
    "write_result",
]

CONFIG_FILE = "config.json"
LATEST_FILE = "checkpoint_latest.pt"
BEST_FILE = "checkpoint_best.pt"
POLICY_FILE = "policy.pt"
METRICS_FILE = "metrics.csv"
_SEALED = "learn-checkpoint-sealed-v1"  # outer format: payload + SHA-256
#: Written when a run ends normally (budget or time limit reached); absent = unfinished.
RESULT_FILE = "result.json"


class CorruptFileError(InputError):
    """A run-directory file exists but cannot be read (truncated, wrong format)."""


def check_run_dir(run_dir: Path, resume: bool) -> Path:
    """The run directory of a training, checked before any work: to start a run it must be
    absent or an empty folder (its parent a folder); to resume, a folder. Raises
    `InputError` naming the problem."""
    p = Path(run_dir)
    # names that fit, a folder that takes files; checked here, created once the work starts
    files.check_output_dir(p, "run directory")
    if resume:
        if not p.is_dir():
            raise InputError(f"cannot resume: run directory {p} does not exist")
        return p
    if p.exists() and any(p.iterdir()):
        raise InputError(f"run directory {p} exists and is not empty; pass --resume to "
                         "continue it or choose a new --out")
    return p


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see either the old or the new file
    (`finsler.infra.files.atomic_write_bytes`: symlinks written through, special files
    refused, failed writes leave the old file)."""
    files.atomic_write_bytes(path, data)


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def save_checkpoint(path: Path, obj: dict[str, Any]) -> None:
    """``torch.save`` to memory, then atomic write. The file holds the serialised ``obj``
    and its SHA-256, so that `load_checkpoint` detects any damaged byte (a torch
    archive alone loads bit-flipped tensors without complaint)."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    payload = buf.getvalue()
    outer = io.BytesIO()
    torch.save({"format": _SEALED, "sha256": hashlib.sha256(payload).hexdigest(),
                "payload": payload}, outer)
    atomic_write_bytes(path, outer.getvalue())


def load_checkpoint(path: Path) -> dict[str, Any]:
    """Load a checkpoint written by `save_checkpoint` (tensors and plain data only;
    files of the earlier unsealed format, such as shipped policies, load too).

    Raises `InputError` if missing and `CorruptFileError` if unreadable,
    truncated or damaged (checksum mismatch).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"checkpoint {path} does not exist")
    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
        if isinstance(obj, dict) and obj.get("format") == _SEALED:
            payload = obj.get("payload")
            if not isinstance(payload, bytes) or \
                    hashlib.sha256(payload).hexdigest() != obj.get("sha256"):
                raise CorruptFileError(f"checkpoint {path} is corrupt: its checksum does not "
                                       "match its content")
            obj = torch.load(io.BytesIO(payload), map_location="cpu", weights_only=True)
    except CorruptFileError:
        raise
    except Exception as err:  # torch raises many types for truncated / foreign files
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise CorruptFileError(f"checkpoint {short(str(path), 80)} is corrupt or unreadable: "
                               f"{short(first, 120)}") from err
    if not isinstance(obj, dict) or obj.get("format") != "learn-checkpoint-v1":
        raise CorruptFileError(f"checkpoint {path} is not a learn checkpoint")
    return obj


def read_json(path: Path) -> dict[str, Any]:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path} does not exist")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError) as err:  # nesting too deep too
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise CorruptFileError(f"{short(str(path), 80)} is not valid JSON: "
                               f"{short(first, 120)}") from err
    if not isinstance(doc, dict):
        raise CorruptFileError(f"{path} does not hold a JSON object")
    return doc


def write_metrics(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write the metrics log (CSV, one row per evaluation) atomically."""
    if not rows:
        return
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    atomic_write_text(path, buf.getvalue())


def read_metrics(path: Path) -> list[dict[str, Any]]:
    """Rows of a metrics log (numbers parsed); an absent file gives no rows."""
    path = Path(path)
    if not path.is_file():
        return []
    with path.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    out = []
    for r in rows:
        parsed: dict[str, Any] = {}
        for k, v in r.items():
            try:
                parsed[k] = int(v)
            except (TypeError, ValueError):
                try:
                    parsed[k] = float(v)
                except (TypeError, ValueError):
                    parsed[k] = v
        out.append(parsed)
    return out


def write_result(run_dir: Path, final: dict[str, Any], best: dict[str, Any],
                 stopped_by: str, extra: dict[str, Any] | None = None) -> None:
    """Mark a run finished: ``result.json`` with the all-inclusive and paper counts of
    evaluations of C, wall time, which bound stopped it, the last metrics row and the best
    (validation-selected) checkpoint's figures, plus a method's ``extra`` entries."""
    doc = {
        "timesteps": int(final["timesteps"]),
        "timesteps_paper": int(final.get("timesteps_paper", final["timesteps"])),
        "timesteps_derivative": int(final.get("timesteps_derivative", 0)),
        "wall_seconds": float(final["wall_seconds"]),
        "stopped_by": stopped_by,
        "final": dict(final),
        "best": dict(best),
        **(extra or {}),
    }
    atomic_write_text(Path(run_dir) / RESULT_FILE, json.dumps(doc, indent=2))


def restore_history(run_dir: Path, state: dict[str, Any], iteration: int) -> list[dict[str, Any]]:
    """The metrics rows of a run being resumed at ``iteration``: the copy kept inside the
    checkpoint (authoritative: a truncated or damaged ``metrics.csv`` loses nothing), or,
    for checkpoints written before that copy existed, the rows of ``metrics.csv``."""
    rows = state.get("history")
    if rows is None:
        rows = read_metrics(Path(run_dir) / METRICS_FILE)
    return [dict(r) for r in rows if int(r["iteration"]) <= iteration]
