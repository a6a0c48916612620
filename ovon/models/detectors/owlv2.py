"""OWLv2 open-vocabulary detector (the paper's), loaded only from local files.

Uses transformers' `Owlv2ForObjectDetection` with the PIL image processor of transformers 5
(`Owlv2ImageProcessorPil`; never `AutoImageProcessor`, which wants torchvision) and the model's own CLIP
tokenizer. The goal text, inserted into `DetectorConfig.owlv2_prompt`, is the only query. OWLv2 gives boxes,
not masks: lifting uses the box's central part (`LiftConfig.box_shrink`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ovon.models.config import DetectorConfig
from ovon.models.detectors.base import Detection
from ovon.models.hf import load_pretrained


def load_owlv2(name_or_path: str, device: str = "cpu") -> tuple[Any, Any, Any]:
    """(model, image_processor, tokenizer) from the local cache/folder; `ModelNotAvailableError` at once
    (one line naming the model and how to get it) when the files are missing."""

    def classes() -> tuple[Any, Any, Any]:
        from transformers import AutoTokenizer, Owlv2ForObjectDetection, Owlv2ImageProcessorPil

        return Owlv2ForObjectDetection, Owlv2ImageProcessorPil, AutoTokenizer

    def missing(e: Exception) -> str:
        return (
            f"OWLv2 model {name_or_path!r} is not available locally ({type(e).__name__}); weights are never "
            f"downloaded at run time: on a machine with internet run `hf download {name_or_path}` and copy "
            f"~/.cache/huggingface here (or set HF_HOME), or set detector.owlv2_model to a save_pretrained "
            f"folder; without weights use detector.kind=oracle (oracle detection)"
        )

    return load_pretrained("owlv2", name_or_path, device, classes, missing)


class OWLv2Detector:
    name = "OWLv2"
    privileged = False

    def __init__(self, cfg: DetectorConfig | None = None, text_encoder=None) -> None:
        del text_encoder  # OWLv2 embeds the query with its own text tower
        self.cfg = cfg or DetectorConfig(kind="owlv2")
        self.model, self.processor, self.tokenizer = load_owlv2(self.cfg.owlv2_model, self.cfg.device)
        self.max_text = int(self.model.config.text_config.max_position_embeddings)
        self._text_cache: dict[str, dict[str, torch.Tensor]] = {}

    def reset(self, seed: int) -> None:
        del seed  # deterministic

    def _text_inputs(self, goal: str) -> dict[str, torch.Tensor]:
        if goal not in self._text_cache:
            tok = self.tokenizer(
                [self.cfg.owlv2_prompt.format(goal=goal)],
                padding="max_length",
                truncation=True,
                max_length=self.max_text,
                return_tensors="pt",
            )
            self._text_cache[goal] = {k: v.to(self.cfg.device) for k, v in tok.items()}
        return self._text_cache[goal]

    @torch.inference_mode()
    def detect(self, observation: dict, goal_text: str) -> list[Detection]:
        from PIL import Image

        rgb = np.asarray(observation["rgb"])
        if rgb.dtype != np.uint8 or rgb.ndim != 3:
            raise TypeError(f"OWLv2 expects an (H, W, 3) uint8 RGB frame, got {rgb.dtype} {rgb.shape}")
        h, w = rgb.shape[:2]
        pixels = self.processor(images=[Image.fromarray(rgb)], return_tensors="pt")["pixel_values"]
        text = self._text_inputs(goal_text)
        out = self.model(
            input_ids=text["input_ids"],
            attention_mask=text["attention_mask"],
            pixel_values=pixels.to(self.cfg.device),
        )
        res = self.processor.post_process_object_detection(
            out, threshold=self.cfg.owlv2_threshold, target_sizes=[(h, w)]
        )[0]
        dets = []
        for score, b in zip(res["scores"].tolist(), res["boxes"].tolist()):
            x0, y0 = max(0, int(np.floor(b[0]))), max(0, int(np.floor(b[1])))
            x1, y1 = min(w, int(np.ceil(b[2]))), min(h, int(np.ceil(b[3])))
            if x1 > x0 and y1 > y0:  # boxes are relative to the padded square: clip to the frame
                dets.append(Detection(box=(x0, y0, x1, y1), score=float(score), label=goal_text))
        dets.sort(key=lambda d: -d.score)
        return dets
