"""Model files: JSON or NPZ (loaded with allow_pickle=False), never pickle, with a format version.

A model file names the profile it was trained for (name + hash, ``Profile.identity``) and is used
only with that profile (``check_model_for``); a file that could drive the arm in a way its
profile does not allow (NaN or empty amplitude ranges, classes or nodes the profile lacks) is
refused on loading, and never written.

JSON floats are written with Python's shortest round-trip repr, so a loaded model's parameters are
bit-identical to the trained model's and it predicts exactly the same.
"""
from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from bomi.classifier import AmplitudeRange, Model, PostProcessing, ProfileIdentity, model_defects
from bomi.errors import BomiError
from bomi.features import FeatureSpec, features
from bomi.files import check_input, write_bytes
from bomi.profiles import Profile

FORMAT_NAME = "bomi-model"
FORMAT_VERSION = 2  # 2: the profile's identity
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
        "profile": None if model.profile is None else {"name": model.profile.name, "sha256": model.profile.digest},
    }


def save_model(path: str | os.PathLike, model: Model, *, overwrite: bool = False) -> None:
    """Write ``model`` as .json or .npz (by suffix), atomically; an existing file only if ``overwrite``.

    A model its own loader would refuse is not written (BomiError naming the file).
    """
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise BomiError(f"{path}: model files must end in .json or .npz")
    defects = model_defects(model) + ([] if model.profile is not None else ["it names no profile"])
    if defects:
        raise BomiError(f"{path}: not written, the trained model is unusable: {'; '.join(defects)}")
    meta = _metadata(model)
    if path.suffix.lower() == ".json":
        payload = json.dumps({**meta, "classes": model.classes.tolist(), "coef": model.coef.tolist(),
                              "intercept": model.intercept.tolist()}, indent=1).encode()
    else:
        buffer = io.BytesIO()
        np.savez(buffer, meta=np.array(json.dumps(meta)), classes=model.classes, coef=model.coef,
                 intercept=model.intercept)
        payload = buffer.getvalue()
    write_bytes(path, payload, overwrite=overwrite)


def load_model(path: str | os.PathLike) -> Model:
    """Read and validate a model file; any defect raises BomiError naming the file."""
    path = check_input(path, "model")
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(data, dict):
                raise ValueError("not a JSON object")
            meta, arrays = data, {k: data.get(k) for k in ("classes", "coef", "intercept")}
        elif path.suffix.lower() == ".npz":
            if not zipfile.is_zipfile(path):
                raise ValueError("not an NPZ archive")
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
    except RecursionError:
        raise BomiError(f"{path}: not a valid bomi model (nested too deeply)") from None
    except (ValueError, TypeError, AttributeError, OSError, zipfile.BadZipFile, UnicodeDecodeError,
            OverflowError, EOFError) as exc:
        message = str(exc) or type(exc).__name__
        raise BomiError(f"{path}: not a valid bomi model ({message})") from None


def _amplitude_range(label: str, entry: dict) -> AmplitudeRange:
    """One class's amplitude range; ``direction`` (a unit 3-vector) only for "along_class" models."""
    if not isinstance(entry, dict):
        raise ValueError(f"amplitude of class {label}: not an object")
    direction = entry.get("direction")
    if direction is not None:
        direction = tuple(float(v) for v in direction)
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
    profile = meta.get("profile")
    if not (isinstance(profile, dict) and isinstance(profile.get("name"), str)
            and isinstance(profile.get("sha256"), str)):
        raise ValueError("it does not name the profile it was trained for (name and sha256); retrain it")
    n_features = features(spec.kind, np.zeros((1, spec.window, len(spec.components)))).shape[1]
    if coef.shape != (len(classes), n_features) or intercept.shape != (len(classes),):
        raise ValueError(f"coef/intercept shapes {coef.shape}/{intercept.shape} do not fit "
                         f"{len(classes)} classes x {n_features} {spec.kind} features")
    if not (np.all(np.isfinite(coef)) and np.all(np.isfinite(intercept))):
        raise ValueError("non-finite LDA parameters")
    amplitude = {int(label): _amplitude_range(label, r) for label, r in meta["amplitude"].items()}
    post = meta["post_processing"]
    model = Model(classes=classes.astype(np.int64), coef=coef, intercept=intercept, spec=spec, amplitude=amplitude,
                  post=PostProcessing(rejection_threshold=post["rejection_threshold"],
                                      vote_length=int(post["vote_length"])),
                  shrinkage=meta.get("shrinkage"), profile=ProfileIdentity(profile["name"], profile["sha256"]))
    defects = model_defects(model)
    if defects:
        raise ValueError("; ".join(defects))
    return model


def check_model_for(model: Model, profile: Profile, source: str | os.PathLike) -> None:
    """BomiError unless ``model`` was trained for ``profile`` as it is now (same name and hash) and
    every class it can decide, with its amplitude node, is one of the profile's."""
    identity = profile.identity
    if model.profile is None:
        raise BomiError(f"{source}: the model does not say which profile it was trained for")
    if model.profile.name != identity.name:
        raise BomiError(f"{source}: model trained for profile {model.profile.name}, not {identity.name} "
                        f"({profile.source})")
    if model.profile.digest != identity.digest:
        raise BomiError(f"{source}: model trained for another version of profile {identity.name} (its nodes, "
                        f"classes, joystick functions or features differ from {profile.source}); retrain it")
    unknown = sorted(set(model.classes.tolist()) - {cls.label for cls in profile.classes})
    if unknown:
        raise BomiError(f"{source}: class(es) {unknown} are not classes of profile {profile.name}")
    class_nodes = profile.class_nodes
    wrong = sorted(label for label, r in model.amplitude.items() if class_nodes.get(label) != r.node)
    if wrong:
        raise BomiError(f"{source}: amplitude node of class(es) {wrong} differs from profile {profile.name}")
    missing = sorted(set(model.spec.nodes) - set(profile.node_indices))
    if missing:
        raise BomiError(f"{source}: the model needs node(s) {missing} the profile {profile.name} does not define")
