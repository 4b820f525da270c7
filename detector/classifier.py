"""The baseline's classifier: multinomial logistic regression over colour and texture features.

Small and transparent: standardised features (:mod:`detector.features`), one weight vector and
bias per class, softmax probabilities; fitted by L-BFGS on the class-balanced cross-entropy with
an L2 penalty (no randomness: the same samples give the same model). The model is a small JSON
file that records its class names, feature names and what it was trained on; loading checks
every field and names the one that is wrong.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from detector.errors import DetectorConfigError, ModelFileError
from detector.features import FEATURE_NAMES
from interfaces.fileio import write_atomic

FORMAT = "cdw-twin detector colour classifier"
"""The ``format`` field of a classifier file."""
VERSION = 1

DEFAULT_L2 = 0.01
"""The L2 penalty fits use by default (on standardised features; 0.01 gave the best held-out
class accuracy on the shared sample's photos and on renders of its pieces, against 0.1 and 1)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class ColourClassifier:
    """A fitted model: ``weights`` ``(C, F)``, ``bias`` ``(C,)``, feature ``mean`` and
    ``scale`` ``(F,)``; ``feature_stride`` the pixel step its features were computed with (the
    detector computes them the same way); ``training`` says what it learnt from (plain
    data)."""

    class_names: tuple[str, ...]
    feature_names: tuple[str, ...]
    mean: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    bias: np.ndarray
    l2: float
    feature_stride: int = 2
    training: dict[str, object] = field(default_factory=dict)

    def probabilities(self, features: np.ndarray) -> np.ndarray:
        """Class probabilities ``(n, C)`` of ``features`` ``(n, F)``."""
        z = (np.asarray(features, dtype=np.float64) - self.mean) / self.scale
        logits = z @ self.weights.T + self.bias
        logits -= logits.max(axis=1, keepdims=True)
        p = np.exp(logits)
        out: np.ndarray = p / p.sum(axis=1, keepdims=True)
        return out

    def predict(self, features: np.ndarray) -> tuple[list[str], np.ndarray]:
        """The most probable class of each row of ``features`` and its probability ``(n,)``."""
        p = self.probabilities(features)
        best = p.argmax(axis=1) if len(p) else np.zeros(0, dtype=np.intp)
        return [self.class_names[i] for i in best], p[np.arange(len(p)), best]

    def to_data(self) -> dict[str, object]:
        """The model as plain JSON data."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "class_names": list(self.class_names),
            "feature_names": list(self.feature_names),
            "mean": self.mean.tolist(),
            "scale": self.scale.tolist(),
            "weights": self.weights.tolist(),
            "bias": self.bias.tolist(),
            "l2": self.l2,
            "feature_stride": self.feature_stride,
            "training": self.training,
        }

    def save(self, path: Path) -> None:
        """Write the model to ``path`` (JSON, atomically)."""
        write_atomic(Path(path), json.dumps(self.to_data(), indent=1) + "\n")

    @classmethod
    def load(cls, path: Path) -> ColourClassifier:
        """Read a model written by :meth:`save`."""
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            msg = f"{path}: cannot read a classifier: {exc}"
            raise ModelFileError(msg) from exc
        return cls.from_data(data, str(path))

    @classmethod
    def from_data(cls, data: object, where: str) -> ColourClassifier:
        """A model from plain data; errors name ``where`` and the field."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            msg = f"{where}: not a classifier file (format must be {FORMAT!r})"
            raise ModelFileError(msg)
        if data.get("version") != VERSION:
            msg = f"{where}: version = {data.get('version')!r}, this detector reads {VERSION}"
            raise ModelFileError(msg)
        names = _strings(data, "class_names", where)
        features = _strings(data, "feature_names", where)
        if features != FEATURE_NAMES:
            msg = (
                f"{where}: feature_names = {list(features)}, "
                f"this detector computes {list(FEATURE_NAMES)}"
            )
            raise ModelFileError(msg)
        c, f = len(names), len(features)
        l2 = data.get("l2")
        if isinstance(l2, bool) or not isinstance(l2, int | float) or not l2 >= 0:
            msg = f"{where}: l2 = {l2!r}: must be a number >= 0"
            raise ModelFileError(msg)
        stride = data.get("feature_stride", 2)
        if isinstance(stride, bool) or not isinstance(stride, int) or not 1 <= stride <= 8:
            msg = f"{where}: feature_stride = {stride!r}: must be an int in [1, 8]"
            raise ModelFileError(msg)
        training = data.get("training", {})
        if not isinstance(training, dict):
            msg = f"{where}: training = {training!r}: must be a mapping"
            raise ModelFileError(msg)
        scale = _array(data, "scale", (f,), where)
        if (scale <= 0).any():
            msg = f"{where}: scale: every value must be > 0"
            raise ModelFileError(msg)
        return cls(
            class_names=names,
            feature_names=features,
            mean=_array(data, "mean", (f,), where),
            scale=scale,
            weights=_array(data, "weights", (c, f), where),
            bias=_array(data, "bias", (c,), where),
            l2=float(l2),
            feature_stride=stride,
            training=training,
        )


def _strings(data: dict[str, object], key: str, where: str) -> tuple[str, ...]:
    value = data.get(key)
    if (
        not isinstance(value, list)
        or not value
        or not all(isinstance(v, str) and v for v in value)
        or len(set(value)) != len(value)
    ):
        msg = f"{where}: {key} = {value!r}: must be a list of distinct non-empty names"
        raise ModelFileError(msg)
    return tuple(value)


def _array(data: dict[str, object], key: str, shape: tuple[int, ...], where: str) -> np.ndarray:
    try:
        out = np.array(data.get(key), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        msg = f"{where}: {key}: not an array of numbers: {exc}"
        raise ModelFileError(msg) from exc
    if out.shape != shape or not np.isfinite(out).all():
        msg = f"{where}: {key}: expected finite numbers of shape {shape}, got {out.shape}"
        raise ModelFileError(msg)
    return out


def fit_classifier(
    features: np.ndarray,
    labels: Sequence[str],
    *,
    class_names: Sequence[str] | None = None,
    l2: float = DEFAULT_L2,
    feature_stride: int = 2,
    training: dict[str, object] | None = None,
) -> ColourClassifier:
    """Fit a model to ``features`` ``(n, F)`` and their class ``labels`` (n names).

    ``class_names`` fixes the model's classes and their order (default: the labels' sorted);
    a class without samples keeps a large negative bias (never predicted). Samples are weighted
    so each present class counts equally; ``l2`` penalises the squared weights (on
    standardised features); ``feature_stride`` is recorded (the pixel step of the features).
    """
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] != len(labels) or x.shape[1] != len(FEATURE_NAMES):
        msg = (
            f"features: shape {x.shape} for {len(labels)} labels and {len(FEATURE_NAMES)} features"
        )
        raise DetectorConfigError(msg)
    if not np.isfinite(x).all():
        msg = "features: not all finite"
        raise DetectorConfigError(msg)
    names = tuple(class_names) if class_names is not None else tuple(sorted(set(labels)))
    unknown = sorted(set(labels) - set(names))
    if unknown or not names:
        msg = f"labels: classes {unknown} are not among class_names {list(names)}"
        raise DetectorConfigError(msg)
    if not math.isfinite(l2) or l2 < 0:
        msg = f"l2 = {l2!r}: must be >= 0"
        raise DetectorConfigError(msg)
    y = np.array([names.index(label) for label in labels], dtype=np.intp)
    mean = x.mean(axis=0) if len(x) else np.zeros(x.shape[1])
    scale = x.std(axis=0) if len(x) else np.ones(x.shape[1])
    scale = np.where(scale > 1e-9, scale, 1.0)
    z = (x - mean) / scale
    c, f = len(names), x.shape[1]
    counts = np.bincount(y, minlength=c).astype(np.float64)
    present = counts > 0
    sample_w = (1.0 / np.maximum(counts, 1.0))[y] / max(int(present.sum()), 1)
    onehot = np.zeros((len(y), c))
    onehot[np.arange(len(y)), y] = 1.0

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        w = theta[: c * f].reshape(c, f)
        b = theta[c * f :]
        logits = z @ w.T + b
        logits -= logits.max(axis=1, keepdims=True)
        p = np.exp(logits)
        p /= p.sum(axis=1, keepdims=True)
        value = -float((sample_w * np.log(p[np.arange(len(y)), y] + 1e-300)).sum())
        value += 0.5 * l2 * float((w * w).sum()) / max(len(y), 1)
        residual = (p - onehot) * sample_w[:, None]
        grad_w = residual.T @ z + l2 * w / max(len(y), 1)
        grad_b = residual.sum(axis=0)
        return value, np.concatenate((grad_w.ravel(), grad_b))

    result = minimize(loss, np.zeros(c * f + c), jac=True, method="L-BFGS-B")
    weights = result.x[: c * f].reshape(c, f)
    bias = result.x[c * f :].copy()
    bias[~present] = -50.0
    info = dict(training or {})
    info.setdefault("samples_per_class", {n: int(k) for n, k in zip(names, counts, strict=True)})
    return ColourClassifier(
        class_names=names,
        feature_names=FEATURE_NAMES,
        mean=mean,
        scale=scale,
        weights=weights,
        bias=bias,
        l2=float(l2),
        feature_stride=feature_stride,
        training=info,
    )


__all__ = ["DEFAULT_L2", "FORMAT", "VERSION", "ColourClassifier", "fit_classifier"]
