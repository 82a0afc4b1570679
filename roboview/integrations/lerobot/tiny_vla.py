"""A tiny, randomly initialised VLA backbone written offline, to check a VLA's plumbing on RoboView data.

    python -m roboview.integrations.lerobot.tiny_vla --output_dir=outputs/tiny_smolvlm [--type=smolvla|xvla]

writes a SmolVLM config and processor (no weights: `--policy.load_vlm_weights=false` builds the model
from the config with random weights), or XVLA's tokenizer (its tiny Florence-2 config travels in the flags),
and prints the `lerobot-train` flags that train the policy on it:

    lerobot-train --dataset.repo_id=ID --dataset.root=DIR --policy.type=smolvla \
        --policy.vlm_model_name=outputs/tiny_smolvlm --policy.load_vlm_weights=false \
        --policy.resize_imgs_with_padding=64,64 --policy.num_vlm_layers=4 ...

Nothing is downloaded: the tokenizer is a `tokenizers` word-level vocabulary over every word of the
benchmark's instructions (plus SmolVLM's special image tokens), so the instruction a policy receives
can be decoded back word for word. A policy built this way acts at random (success 0): it exists to
show that RoboView's cameras, 8-D state and action, and the instruction reach a VLA's inputs — in
training, in `roboview.pipelines.evaluate --policy.type=lerobot` and in `lerobot-eval --env.type=roboview`. A user
with real weights passes `--policy.path=lerobot/smolvla_base` (or `lerobot/pi05_base`) instead.

Which LeRobot VLA types can be built this way, and why the others cannot: docs/vla.md.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

# SmolVLM's special tokens, in the roles its processor and SmolVLA's model look them up by.
SPECIAL_TOKENS = {
    "pad_token": "<pad>",
    "unk_token": "<unk>",
    "bos_token": "<|im_start|>",
    "eos_token": "<end_of_utterance>",
}
IMAGE_TOKENS = {
    "fake_image_token": "<fake_token_around_image>",
    "image_token": "<image>",
    "global_image_token": "<global-img>",
    "end_of_utterance_token": "<end_of_utterance>",
}
# The tiny model: 4 text layers 64 wide, a 2-layer 32-wide vision tower over 64-pixel images in 16-pixel
# patches (16 patches, 4 image tokens after SmolVLM's 2x pixel shuffle).
IMAGE_SIZE = 64
TEXT_LAYERS = 4


def instruction_words() -> list[str]:
    """Every word of every instruction (pick_place and push), and every word the Semantic Grounding Layer
    may put into one (color names and categories, shapes, sizes), in first-seen order."""
    from roboview.policies.vlm.sgl import GENERIC_NOUNS, PRIORITY
    from roboview.variation.colors import CATEGORIES
    from roboview.variation.factors import FACTORS

    texts = [
        *PRIORITY,
        *CATEGORIES,
        *GENERIC_NOUNS,
        "block",
        "prism",
        "small",
        "large",
        "medium",
        "big",
        "left",
        "right",
        "front",
        "back",
    ]
    for factor in FACTORS.values():
        if factor.name.endswith(("instruction", "shape")) or factor.name == "color":
            texts += [str(v).replace("_", " ") for v in factor.values]
    words: dict[str, None] = {}
    for text in texts:
        words.update(dict.fromkeys(re.findall(r"[\w']+|[^\w\s]", text.lower())))
    return list(words)


def write_smolvlm(output_dir: str | Path, extra_words: tuple[str, ...] = ()) -> Path:
    """A SmolVLM config + processor (tokenizer, image processor) in `output_dir`; returns the folder."""
    from tokenizers import Tokenizer, models, pre_tokenizers
    from transformers import (
        PreTrainedTokenizerFast,
        SmolVLMConfig,
        SmolVLMImageProcessor,
        SmolVLMProcessor,
        SmolVLMVideoProcessor,
    )

    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    special = list(dict.fromkeys([*SPECIAL_TOKENS.values(), *IMAGE_TOKENS.values()]))
    words = [w for w in dict.fromkeys([*instruction_words(), *extra_words]) if w not in special]
    vocab = {token: i for i, token in enumerate(special + words)}
    backend = Tokenizer(models.WordLevel(vocab, unk_token=SPECIAL_TOKENS["unk_token"]))
    backend.pre_tokenizer = pre_tokenizers.Whitespace()
    tokenizer = PreTrainedTokenizerFast(
        tokenizer_object=backend, extra_special_tokens=IMAGE_TOKENS, **SPECIAL_TOKENS
    )
    images = SmolVLMImageProcessor(
        do_resize=True,
        size={"longest_edge": IMAGE_SIZE},
        max_image_size={"longest_edge": IMAGE_SIZE},
        do_image_splitting=False,
    )
    SmolVLMProcessor(
        image_processor=images, tokenizer=tokenizer, video_processor=SmolVLMVideoProcessor(), image_seq_len=4
    ).save_pretrained(out)
    config = SmolVLMConfig(
        text_config=dict(
            model_type="llama",
            vocab_size=len(vocab),
            hidden_size=64,
            intermediate_size=128,
            num_hidden_layers=TEXT_LAYERS,
            num_attention_heads=4,
            num_key_value_heads=2,
            head_dim=16,
            max_position_embeddings=512,
            pad_token_id=vocab[SPECIAL_TOKENS["pad_token"]],
        ),
        vision_config=dict(
            hidden_size=32,
            intermediate_size=64,
            num_hidden_layers=2,
            num_attention_heads=2,
            image_size=IMAGE_SIZE,
            patch_size=16,
        ),
        scale_factor=2,
        image_token_id=vocab[IMAGE_TOKENS["image_token"]],
    )
    config.save_pretrained(out)
    return out.resolve()  # a checkpoint records this path: it must not depend on the working directory


BART_SPECIAL = ("<s>", "<pad>", "</s>", "<unk>", "<mask>", "<image>")


def _bart_vocabulary() -> dict[str, int]:
    return {token: i for i, token in enumerate([*BART_SPECIAL, *instruction_words()])}


def write_bart_tokenizer(output_dir: str | Path) -> Path:
    """A BART-style word-level tokenizer (XVLA's text encoder is BART) over the same vocabulary."""
    from tokenizers import Tokenizer, models, pre_tokenizers, processors
    from transformers import PreTrainedTokenizerFast

    out = Path(output_dir).resolve()
    vocab = _bart_vocabulary()
    backend = Tokenizer(models.WordLevel(vocab, unk_token="<unk>"))
    backend.pre_tokenizer = pre_tokenizers.Whitespace()
    backend.post_processor = processors.TemplateProcessing(
        single="<s> $A </s>", special_tokens=[("<s>", 0), ("</s>", 2)]
    )
    PreTrainedTokenizerFast(
        tokenizer_object=backend,
        bos_token="<s>",
        eos_token="</s>",
        unk_token="<unk>",
        pad_token="<pad>",
        mask_token="<mask>",
    ).save_pretrained(out)
    return out


def xvla_train_flags(tokenizer: str | Path, chunk_size: int = 10) -> list[str]:
    """lerobot-train's --policy.* flags for a tiny XVLA (a 4-stage DaViT of width ≤ 64, a 1-layer BART, a
    2-layer policy transformer; random weights) on RoboView's 8-D joint actions."""
    import json

    vocab_size = len(_bart_vocabulary())
    width = 64  # BART's d_model must equal the vision projection
    florence = {
        "vision_config": {
            "depths": [1, 1, 1, 1],
            "embed_dim": [16, 32, 48, 64],
            "num_heads": [1, 2, 2, 4],
            "num_groups": [1, 2, 2, 4],
            "window_size": 4,
            "projection_dim": width,
            "drop_path_rate": 0.0,
            "max_position_embeddings": 16,
            "max_temporal_embeddings": 4,
        },
        "text_config": {
            "model_type": "bart",
            "vocab_size": vocab_size,
            "d_model": width,
            "encoder_layers": 1,
            "decoder_layers": 1,
            "encoder_attention_heads": 2,
            "decoder_attention_heads": 2,
            "encoder_ffn_dim": 128,
            "decoder_ffn_dim": 128,
            "max_position_embeddings": 128,
            "pad_token_id": 1,
            "bos_token_id": 0,
            "eos_token_id": 2,
        },
        "pad_token_id": 1,
        "bos_token_id": 0,
        "eos_token_id": 2,
        "image_token_id": BART_SPECIAL.index("<image>"),
    }
    return [
        "--policy.type=xvla",
        f"--policy.florence_config={json.dumps(florence)}",
        f"--policy.tokenizer_name={tokenizer}",
        "--policy.tokenizer_max_length=24",
        f"--policy.hidden_size={width}",
        "--policy.depth=2",
        "--policy.num_heads=2",
        "--policy.num_domains=2",
        "--policy.len_soft_prompts=4",
        "--policy.dim_time=16",
        "--policy.max_len_seq=128",
        "--policy.action_mode=auto",
        "--policy.max_action_dim=8",
        "--policy.max_state_dim=8",
        f"--policy.chunk_size={chunk_size}",
        f"--policy.n_action_steps={chunk_size}",
        "--policy.num_denoising_steps=2",
        "--policy.push_to_hub=false",
    ]


def smolvla_train_flags(backbone: str | Path, chunk_size: int = 10) -> list[str]:
    """lerobot-train's --policy.* flags for SmolVLA on the tiny backbone (random weights, no download)."""
    return [
        "--policy.type=smolvla",
        f"--policy.vlm_model_name={backbone}",
        "--policy.load_vlm_weights=false",
        f"--policy.resize_imgs_with_padding=[{IMAGE_SIZE},{IMAGE_SIZE}]",
        f"--policy.num_vlm_layers={TEXT_LAYERS}",
        f"--policy.chunk_size={chunk_size}",
        f"--policy.n_action_steps={chunk_size}",
        "--policy.push_to_hub=false",
    ]


@dataclass
class TinyVLAConfig:
    # Folder to write the backbone files into (SmolVLM config + processor, or XVLA's tokenizer).
    output_dir: str = "outputs/tiny_vla"
    # smolvla or xvla.
    type: str = "smolvla"

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"--type={self.type!r} unknown; allowed: {', '.join(TYPES)}")


TYPES = ("smolvla", "xvla")


def run(cfg: TinyVLAConfig) -> list[str]:
    """Write the backbone files; returns lerobot-train's --policy.* flags for them."""
    if cfg.type == "smolvla":
        return smolvla_train_flags(write_smolvlm(cfg.output_dir))
    return xvla_train_flags(write_bart_tokenizer(cfg.output_dir))


def _summary(cfg: TinyVLAConfig, flags: list[str]) -> None:
    print(
        f"[tiny_vla] {cfg.type} backbone files in {Path(cfg.output_dir).resolve()}; train it with lerobot-train "
        "--dataset.repo_id=ID --dataset.root=DIR " + " ".join(shlex.quote(flag) for flag in flags)
    )


def main(args: list[str] | None = None) -> list[str]:
    from roboview.core.cli import cli_main

    return cli_main(TinyVLAConfig, run, _summary, (ValueError,), args)


if __name__ == "__main__":
    main()
