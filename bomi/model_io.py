"""Model files: JSON or NPZ (loaded with allow_pickle=False), never pickle, with a format version.

A model file names the profile it was trained for (name + hash, ``Profile.identity``) and is used
only with that profile (``check_model_for``); a file that could drive the arm in a way its
profile does not allow (NaN or empty amplitude ranges, classes or nodes the profile lacks) is
refused on loading, and never written.

The file keeps the fitted parameters of each step of the classifier's pipeline (StandardScaler,
PCA, LDA: ``bomi.classifier.PipelineParameters``); loading composes them into the one linear
discriminant with the same function training uses. JSON floats are written with Python's shortest
round-trip repr, so a loaded model's parameters are bit-identical to the trained model's and it
predicts exactly the same.
"""
from __future__ import annotations

import io
import json
import os
import tokenize
import zipfile
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from bomi.classifier import AmplitudeRange, Model, PipelineParameters, PostProcessing, ProfileIdentity, model_defects
from bomi.errors import BomiError
from bomi.features import FeatureSpec, features
from bomi.files import check_input, write_bytes
from bomi.profiles import Profile

FORMAT_NAME = "bomi-model"
FORMAT_VERSION = 3  # 2: the profile's identity; 3: the pipeline's parameters (standardised features)
SUFFIXES = (".json", ".npz")
ARRAYS = ("classes",) + tuple(f.name for f in fields(PipelineParameters))


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
        "amplitude_scales": list(model.amplitude_scales),
        "cv_accuracy": model.cv_accuracy,
        "training_runs": list(model.training_runs),
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
    arrays = {"classes": model.classes, **{f.name: getattr(model.parameters, f.name) for f in fields(PipelineParameters)}}
    if path.suffix.lower() == ".json":
        payload = json.dumps({**meta, **{k: v.tolist() for k, v in arrays.items()}}, indent=1).encode()
    else:
        buffer = io.BytesIO()
        np.savez(buffer, meta=np.array(json.dumps(meta)), **arrays)
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
            meta, arrays = data, {k: data.get(k) for k in ARRAYS}
        elif path.suffix.lower() == ".npz":
            if not zipfile.is_zipfile(path):
                raise ValueError("not an NPZ archive")
            with np.load(path, allow_pickle=False) as npz:
                if "meta" not in npz.files:
                    raise ValueError("missing array meta")
                meta = json.loads(str(npz["meta"]))
                arrays = {k: npz[k] if k in npz.files else None for k in ARRAYS}
        else:
            raise ValueError("model files must end in .json or .npz")
        return _model_from(meta, arrays, path)
    except BomiError:
        raise
    except KeyError as exc:
        raise BomiError(f"{path}: not a valid bomi model (missing field {exc.args[0]!r})") from None
    except RecursionError:
        raise BomiError(f"{path}: not a valid bomi model (nested too deeply)") from None
    except (ValueError, TypeError, AttributeError, OSError, zipfile.BadZipFile, UnicodeDecodeError,
            OverflowError, EOFError, tokenize.TokenError, SyntaxError) as exc:   # the last two: a damaged .npy header
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


def _model_from(meta: dict, arrays: dict, source: Path) -> Model:
    if meta.get("format") != FORMAT_NAME:
        raise ValueError(f"format is {meta.get('format')!r}, expected {FORMAT_NAME!r}")
    if meta.get("version") in (1, 2):
        raise BomiError(f"{source}: model format version {meta['version']} (an LDA on unstandardised features); this "
                        f"program reads version {FORMAT_VERSION}: retrain it with bomi train")
    if meta.get("version") != FORMAT_VERSION:
        raise ValueError(f"format version {meta.get('version')!r}, this program reads version {FORMAT_VERSION}")
    f = meta["features"]
    spec = FeatureSpec(kind=f["kind"], nodes=tuple(int(n) for n in f["nodes"]), window=int(f["window"]),
                       stride=int(f["stride"]))
    missing = [k for k, v in arrays.items() if v is None]
    if missing:
        raise ValueError(f"missing array(s) {', '.join(missing)}")
    classes = np.asarray(arrays["classes"])
    if classes.ndim != 1 or classes.dtype.kind not in "iu" or len(set(classes.tolist())) != len(classes):
        raise ValueError("classes must be distinct integer labels")
    parameters = PipelineParameters(**{f.name: np.asarray(arrays[f.name], dtype=float)
                                       for f in fields(PipelineParameters)})
    profile = meta.get("profile")
    if not (isinstance(profile, dict) and isinstance(profile.get("name"), str)
            and isinstance(profile.get("sha256"), str)):
        raise ValueError("it does not name the profile it was trained for (name and sha256); retrain it")
    n_features = features(spec.kind, np.zeros((1, spec.window, len(spec.components)))).shape[1]
    _check_shapes(parameters, len(classes), n_features, spec.kind)
    amplitude = {int(label): _amplitude_range(label, r) for label, r in meta["amplitude"].items()}
    post = meta["post_processing"]
    cv_accuracy = meta.get("cv_accuracy")
    model = Model(classes=classes.astype(np.int64), parameters=parameters, spec=spec, amplitude=amplitude,
                  post=PostProcessing(rejection_threshold=post["rejection_threshold"],
                                      vote_length=int(post["vote_length"])),
                  shrinkage=meta.get("shrinkage"), profile=ProfileIdentity(profile["name"], profile["sha256"]),
                  amplitude_scales=tuple(float(v) for v in meta.get("amplitude_scales", ())),
                  cv_accuracy=None if cv_accuracy is None else float(cv_accuracy),
                  training_runs=tuple(str(v) for v in meta.get("training_runs", ())))
    defects = model_defects(model)
    if defects:
        raise ValueError("; ".join(defects))
    return model


def _check_shapes(p: PipelineParameters, n_classes: int, n_features: int, kind: str) -> None:
    """ValueError unless the pipeline's arrays fit together, the classes and the features, all finite."""
    rank = p.pca_components.shape[0] if p.pca_components.ndim == 2 else -1
    expected = {"scaler_mean": (n_features,), "scaler_scale": (n_features,), "pca_mean": (n_features,),
                "pca_components": (rank, n_features), "lda_coef": (n_classes, rank),
                "lda_intercept": (n_classes,)}
    for name, shape in expected.items():
        value = getattr(p, name)
        if rank < 1 or value.shape != shape:
            raise ValueError(f"{name} has shape {value.shape}, expected {shape} for {n_classes} classes x "
                             f"{n_features} {kind} features")
        if not np.all(np.isfinite(value)):
            raise ValueError(f"non-finite {name}")
    if not np.all(p.scaler_scale > 0):
        raise ValueError("scaler_scale must be positive")


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
