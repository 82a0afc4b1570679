"""MOKA's transformers backends (OWLv2 detection + SAM masks) on tiny randomly initialised models.

No weights are downloaded: the configs are built here, a few layers of width 32, so the code path a
user runs with `google/owlv2-base-patch16-ensemble` and `facebook/sam-vit-base` is exercised end to
end — processor, forward pass, post-processing, box clipping, masks at image size — without the
real models' quality (their scores are noise).
"""

import json
import string

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.slow

transformers = pytest.importorskip("transformers")

from roboview.policies.vlm.grounding import TransformersGrounder  # noqa: E402
from roboview.policies.vlm.moka import keypoints  # noqa: E402


@pytest.fixture(scope="module")
def tiny_grounder(tmp_path_factory):
    from transformers import (
        CLIPTokenizer,
        Owlv2Config,
        Owlv2ForObjectDetection,
        Owlv2ImageProcessor,
        Owlv2Processor,
        SamConfig,
        SamImageProcessor,
        SamModel,
        SamProcessor,
    )

    folder = tmp_path_factory.mktemp("tok")
    vocab = {}
    for c in [*string.ascii_lowercase, *string.digits, *".,!?'-"]:
        vocab[c] = len(vocab)
        vocab[c + "</w>"] = len(vocab)
    vocab |= {"<|startoftext|>": len(vocab), "<|endoftext|>": len(vocab) + 1}
    (folder / "vocab.json").write_text(json.dumps(vocab))
    (folder / "merges.txt").write_text("#version: 0.2\n")
    tokenizer = CLIPTokenizer(str(folder / "vocab.json"), str(folder / "merges.txt"), model_max_length=16)
    torch.manual_seed(0)
    layers = dict(hidden_size=32, intermediate_size=64, num_hidden_layers=2, num_attention_heads=2)
    owl = Owlv2ForObjectDetection(
        Owlv2Config(
            text_config=dict(vocab_size=len(vocab), max_position_embeddings=16, **layers),
            vision_config=dict(image_size=64, patch_size=16, **layers),
            projection_dim=32,
        )
    ).eval()
    owl_processor = Owlv2Processor(
        image_processor=Owlv2ImageProcessor(size={"height": 64, "width": 64}), tokenizer=tokenizer
    )
    sam = SamModel(
        SamConfig(
            vision_config=dict(
                hidden_size=32,
                intermediate_size=64,
                num_hidden_layers=2,
                num_attention_heads=2,
                image_size=64,
                patch_size=16,
                output_channels=16,
                global_attn_indexes=[1],
                mlp_dim=64,
                window_size=2,
                num_pos_feats=8,
            ),
            prompt_encoder_config=dict(hidden_size=16, image_size=64, patch_size=16, mask_input_channels=4),
            mask_decoder_config=dict(
                hidden_size=16, mlp_dim=32, num_hidden_layers=2, num_attention_heads=2, iou_head_hidden_dim=16
            ),
        )
    ).eval()
    sam_processor = SamProcessor(
        SamImageProcessor(
            size={"longest_edge": 64},
            pad_size={"height": 64, "width": 64},
            mask_size={"longest_edge": 16},
            mask_pad_size={"height": 16, "width": 16},
        )
    )
    return TransformersGrounder("owlv2", owl, owl_processor, sam, sam_processor, threshold=0.0)


def test_owlv2_and_sam_ground_a_description_to_boxes_and_masks(tiny_grounder):
    rgb = (np.random.default_rng(0).random((96, 128, 3)) * 255).astype(np.uint8)
    found = tiny_grounder.detect(rgb, "small red cube")
    # One box per 16x16 patch of the 64x64 input, all kept at threshold 0, less those in the padding.
    assert 0 < len(found) <= 16
    assert [d.score for d in found] == sorted((d.score for d in found), reverse=True)
    for d in found:
        x0, y0, x1, y1 = d.box
        assert 0 <= x0 <= x1 <= 128 and 0 <= y0 <= y1 <= 96
        assert d.mask.shape == (96, 128) and d.mask.dtype == bool
    # MOKA's keypoints come from the mask (or the box when the mask is empty), inside the image.
    points = keypoints(found[0])
    assert len(points) == 5 and all(np.isfinite(points).ravel())


def test_unknown_backend_is_refused():
    with pytest.raises(ValueError, match="allowed: owlv2, grounding_dino"):
        TransformersGrounder("yolo", None, None)


def test_grounding_dino_grounds_a_description_to_boxes(tmp_path):
    from transformers import (
        BertConfig,
        BertTokenizer,
        GroundingDinoConfig,
        GroundingDinoForObjectDetection,
        GroundingDinoImageProcessor,
        GroundingDinoProcessor,
        SwinConfig,
    )

    words = [
        "[PAD]",
        "[UNK]",
        "[CLS]",
        "[SEP]",
        "[MASK]",
        ".",
        *string.ascii_lowercase,
        "small",
        "red",
        "cube",
    ]
    (tmp_path / "vocab.txt").write_text("\n".join(words))
    tokenizer = BertTokenizer(str(tmp_path / "vocab.txt"))
    torch.manual_seed(0)
    model = GroundingDinoForObjectDetection(
        GroundingDinoConfig(
            backbone_config=SwinConfig(
                embed_dim=16,
                depths=[1, 1],
                num_heads=[1, 1],
                window_size=2,
                image_size=64,
                out_features=["stage1", "stage2"],
            ),
            text_config=BertConfig(
                vocab_size=tokenizer.vocab_size,
                hidden_size=32,
                num_hidden_layers=1,
                num_attention_heads=2,
                intermediate_size=64,
                max_position_embeddings=64,
            ),
            d_model=32,
            encoder_layers=1,
            decoder_layers=2,
            encoder_attention_heads=2,
            decoder_attention_heads=2,
            encoder_ffn_dim=64,
            decoder_ffn_dim=64,
            num_queries=10,
            num_feature_levels=2,
            encoder_n_points=2,
            decoder_n_points=2,
            max_text_len=32,
            use_pretrained_backbone=False,
        )
    ).eval()
    processor = GroundingDinoProcessor(
        GroundingDinoImageProcessor(size={"shortest_edge": 64, "longest_edge": 96}), tokenizer
    )
    grounder = TransformersGrounder("grounding_dino", model, processor, threshold=0.0)
    rgb = (np.random.default_rng(1).random((96, 128, 3)) * 255).astype(np.uint8)
    found = grounder.detect(rgb, "Small red cube")
    assert 0 < len(found) <= 10 and all(d.mask is None for d in found)  # no SAM: boxes only
    assert all(0 <= d.box[0] < d.box[2] <= 128 and 0 <= d.box[1] < d.box[3] <= 96 for d in found)
    assert len(keypoints(found[0])) == 5
