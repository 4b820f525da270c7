"""A user's own segmentation model through onnxruntime: the worked example of the plug-in point.

Any instance-segmentation network exported to ONNX with the tensors below plugs into the
detector (:class:`detector.detector.Detector` ``segmenter=``); its masks get the same world
geometry as the baseline's. No weights are downloaded: the model is a file the user gives.

Inputs (by position):

- ``image``: ``float32 (1, 3, H, W)``, RGB in [0, 1], channels first. ``H`` and ``W`` are the
  model's if it fixes them (the frame is resized to them, bilinear) and the frame's if they are
  dynamic;
- optionally a second input ``depth``: ``float32 (1, 1, H, W)``, metres along the optical axis,
  0 where the sensor returned nothing (the segmenter's mode is then ``depth``, else ``colour``).

Outputs (by position; extra outputs are ignored):

- ``masks``: ``float32 (N, h, w)``, one mask logit image per instance (the pixel belongs to the
  instance where the logit is above 0); ``h, w`` may differ from the frame's (nearest-neighbour
  resize back to it);
- ``scores``: ``float32 (N, C)``, class probabilities per instance (rows summing to 1), or logits
  (``scores_are_logits=True``: a softmax is applied). ``C`` matches the class names given beside
  the model: ``class_names=`` or a JSON file ``MODEL.json`` next to ``MODEL.onnx`` holding
  ``{"class_names": [...]}``.

Instances whose best class probability is below ``min_score``, or whose mask is empty, are
dropped. The session runs on one thread (the detector's budget is one core).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from detector.config import Mode
from detector.errors import ModelFileError
from detector.instances import Instance, check_image


def _dims(shape: Sequence[object]) -> tuple[int | None, int | None]:
    """The model's fixed height and width (None where dynamic) of an NCHW input shape."""
    h, w = shape[2], shape[3]
    return (h if isinstance(h, int) else None, w if isinstance(w, int) else None)


class OnnxSegmenter:
    """An ONNX instance-segmentation model as a :class:`detector.instances.Segmenter`."""

    def __init__(
        self,
        model_path: Path,
        *,
        class_names: Sequence[str] | None = None,
        min_score: float = 0.5,
        scores_are_logits: bool = False,
    ) -> None:
        import onnxruntime as ort

        path = Path(model_path)
        if not path.is_file():
            msg = f"{path}: no such ONNX model file"
            raise ModelFileError(msg)
        names = list(class_names) if class_names is not None else _sidecar_names(path)
        if not names or len(set(names)) != len(names) or not all(names):
            msg = f"{path}: class_names = {names!r}: must be distinct non-empty names"
            raise ModelFileError(msg)
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        try:
            self._session = ort.InferenceSession(
                str(path), sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own untyped errors
            msg = f"{path}: onnxruntime cannot load the model: {exc}"
            raise ModelFileError(msg) from exc
        inputs = self._session.get_inputs()
        outputs = self._session.get_outputs()
        if not 1 <= len(inputs) <= 2 or len(inputs[0].shape) != 4:
            msg = f"{path}: expected inputs image (1, 3, H, W) [and depth (1, 1, H, W)]"
            raise ModelFileError(msg)
        if len(outputs) < 2:
            msg = f"{path}: expected outputs masks (N, h, w) and scores (N, C)"
            raise ModelFileError(msg)
        self.path = path
        self.class_names = tuple(names)
        self.min_score = float(min_score)
        self.scores_are_logits = scores_are_logits
        self._inputs = [i.name for i in inputs]
        self._outputs = [o.name for o in outputs[:2]]
        self._size = _dims(inputs[0].shape)

    @property
    def mode(self) -> Mode:
        """``depth`` when the model takes a depth input, else ``colour``."""
        return "depth" if len(self._inputs) == 2 else "colour"

    def segment(self, rgb: np.ndarray, depth_m: np.ndarray | None = None) -> list[Instance]:
        """The model's instances in one image (the :class:`detector.instances.Segmenter`
        protocol)."""
        check_image(rgb, depth_m)
        height, width = rgb.shape[:2]
        h = self._size[0] or height
        w = self._size[1] or width
        image = (
            rgb if (h, w) == (height, width) else _resize(rgb, (w, h), Image.Resampling.BILINEAR)
        )
        feeds = {self._inputs[0]: (image.astype(np.float32) / 255.0).transpose(2, 0, 1)[None]}
        if len(self._inputs) == 2:
            depth = np.zeros((height, width), np.float32) if depth_m is None else depth_m
            depth = np.nan_to_num(depth.astype(np.float32), nan=0.0)
            if (h, w) != (height, width):
                depth = _resize(depth, (w, h), Image.Resampling.NEAREST)
            feeds[self._inputs[1]] = depth[None, None]
        masks, scores = self._session.run(self._outputs, feeds)
        masks = np.asarray(masks, dtype=np.float32)
        scores = np.asarray(scores, dtype=np.float32)
        n = masks.shape[0] if masks.ndim == 3 else -1
        if n < 0 or scores.shape != (n, len(self.class_names)):
            msg = (
                f"{self.path}: outputs masks {masks.shape} and scores {scores.shape} do not "
                f"match (N, h, w) and (N, {len(self.class_names)})"
            )
            raise ModelFileError(msg)
        if self.scores_are_logits and n:
            scores = np.exp(scores - scores.max(axis=1, keepdims=True))
            scores /= scores.sum(axis=1, keepdims=True)
        out = []
        for i in range(n):
            best = int(np.argmax(scores[i]))
            score = float(scores[i, best])
            if score < self.min_score:
                continue
            mask = masks[i] > 0
            if mask.shape != (height, width):
                mask = _resize(mask.astype(np.uint8), (width, height), Image.Resampling.NEAREST) > 0
            if mask.any():
                out.append(Instance(mask=mask, class_name=self.class_names[best], score=score))
        return out


def _resize(image: np.ndarray, size: tuple[int, int], method: Image.Resampling) -> np.ndarray:
    """``image`` resized to ``size`` (width, height) with Pillow."""
    return np.asarray(Image.fromarray(image).resize(size, method))


def _sidecar_names(path: Path) -> list[str]:
    """Class names from ``MODEL.json`` beside ``MODEL.onnx``."""
    side = path.with_suffix(".json")
    try:
        data = json.loads(side.read_text(encoding="utf-8"))
    except FileNotFoundError:
        msg = f'{path}: give class_names, or put them in {side} as {{"class_names": [...]}}'
        raise ModelFileError(msg) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        msg = f"{side}: cannot read the class names: {exc}"
        raise ModelFileError(msg) from exc
    names = data.get("class_names") if isinstance(data, dict) else None
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        msg = f"{side}: class_names = {names!r}: must be a list of names"
        raise ModelFileError(msg)
    return names


__all__ = ["OnnxSegmenter"]
