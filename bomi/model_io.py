"""Model files: JSON or NPZ (loaded with allow_pickle=False), never pickle, with a format version.

JSON floats are written with Python's shortest round-trip repr, so a loaded model's parameters are
bit-identical to the trained model's and it predicts exactly the same.
"""
from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from bomi.classifier import AmplitudeRange, Model, PostProcessing
from bomi.errors import BomiError
from bomi.features import FeatureSpec, features

FORMAT_NAME = "bomi-model"
FORMAT_VERSION = 1
SUFFIXES = (".json", ".npz")


def _metadata(model: Model) -> dict[str, Any]:
    spec = model.spec
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "features": {"kind": spec.kind, "nodes": list(spec.nodes), "window": spec.window, "stride": spec.stride},
        "amplitude": {str(label): {"node": r.node, "gamma_min": r.gamma_min, "gamma_max": r.gamma_max,
                                   **({} if r.direction is None else {"direction": list(r.direction)})}
                      for label, r in sorted(model.amplitude.items())},
        "post_processing": {"rejection_threshold": model.post.rejection_threshold,
                            "vote_length": model.post.vote_length},
        "shrinkage": model.shrinkage,
    }


def save_model(path: str | os.PathLike, model: Model) -> None:
    """Write ``model`` as .json or .npz (by suffix); the target is replaced atomically."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise BomiError(f"{path}: model files must end in .json or .npz")
    meta = _metadata(model)
    if path.suffix.lower() == ".json":
        payload = json.dumps({**meta, "classes": model.classes.tolist(), "coef": model.coef.tolist(),
                              "intercept": model.intercept.tolist()}, indent=1).encode()
    else:
        buffer = io.BytesIO()
        np.savez(buffer, meta=np.array(json.dumps(meta)), classes=model.classes, coef=model.coef,
                 intercept=model.intercept)
        payload = buffer.getvalue()
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as out:
            out.write(payload)
        os.replace(temp, path)
    except BaseException:
        os.unlink(temp)
        raise


def load_model(path: str | os.PathLike) -> Model:
    """Read and validate a model file; any defect raises BomiError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise BomiError(f"{path}: no such model file")
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(data, dict):
                raise ValueError("not a JSON object")
            meta, arrays = data, {k: data.get(k) for k in ("classes", "coef", "intercept")}
        elif path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as npz:
                missing = {"meta", "classes", "coef", "intercept"} - set(npz.files)
                if missing:
                    raise ValueError(f"missing array(s) {', '.join(sorted(missing))}")
                meta = json.loads(str(npz["meta"]))
                arrays = {k: npz[k] for k in ("classes", "coef", "intercept")}
        else:
            raise ValueError("model files must end in .json or .npz")
        return _model_from(meta, arrays)
    except BomiError:
        raise
    except KeyError as exc:
        raise BomiError(f"{path}: not a valid bomi model (missing field {exc.args[0]!r})") from None
    except (ValueError, TypeError, AttributeError, OSError, zipfile.BadZipFile, UnicodeDecodeError) as exc:
        message = str(exc) or type(exc).__name__
        raise BomiError(f"{path}: not a valid bomi model ({message})") from None


def _amplitude_range(label: str, entry: dict) -> AmplitudeRange:
    """One class's amplitude range; ``direction`` (a unit 3-vector) only for "along_class" models."""
    direction = entry.get("direction")
    if direction is not None:
        direction = tuple(float(v) for v in direction)
        if len(direction) != 3 or not abs(np.linalg.norm(direction) - 1.0) < 1e-6:
            raise ValueError(f"amplitude of class {label}: direction must be a unit 3-vector")
    return AmplitudeRange(node=int(entry["node"]), gamma_min=float(entry["gamma_min"]),
                          gamma_max=float(entry["gamma_max"]), direction=direction)


def _model_from(meta: dict, arrays: dict) -> Model:
    if meta.get("format") != FORMAT_NAME:
        raise ValueError(f"format is {meta.get('format')!r}, expected {FORMAT_NAME!r}")
    if meta.get("version") != FORMAT_VERSION:
        raise ValueError(f"format version {meta.get('version')!r}, this program reads version {FORMAT_VERSION}")
    f = meta["features"]
    spec = FeatureSpec(kind=f["kind"], nodes=tuple(int(n) for n in f["nodes"]), window=int(f["window"]),
                       stride=int(f["stride"]))
    classes = np.asarray(arrays["classes"])
    coef = np.asarray(arrays["coef"], dtype=float)
    intercept = np.asarray(arrays["intercept"], dtype=float)
    if classes.ndim != 1 or classes.dtype.kind not in "iu" or len(set(classes.tolist())) != len(classes):
        raise ValueError("classes must be distinct integer labels")
    n_features = features(spec.kind, np.zeros((1, spec.window, len(spec.components)))).shape[1]
    if coef.shape != (len(classes), n_features) or intercept.shape != (len(classes),):
        raise ValueError(f"coef/intercept shapes {coef.shape}/{intercept.shape} do not fit "
                         f"{len(classes)} classes x {n_features} {spec.kind} features")
    if not (np.all(np.isfinite(coef)) and np.all(np.isfinite(intercept))):
        raise ValueError("non-finite LDA parameters")
    amplitude = {int(label): _amplitude_range(label, r) for label, r in meta["amplitude"].items()}
    post = meta["post_processing"]
    return Model(classes=classes.astype(np.int64), coef=coef, intercept=intercept, spec=spec, amplitude=amplitude,
                 post=PostProcessing(rejection_threshold=post["rejection_threshold"], vote_length=int(post["vote_length"])),
                 shrinkage=meta.get("shrinkage"))
