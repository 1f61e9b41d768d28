"""Architecture and noise-schedule settings of the small demo model, stored as ``config.json``."""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from transformers import CLIPVisionConfig

from idpose_core.demo_model.pose_features import FOURIER_DIM
from idpose_core.demo_model.reference_warp import WARP_CHANNELS

ZERO123_POSE_DIM = 4


@dataclass(frozen=True)
class DemoModelConfig:
    """Everything needed to rebuild the model before loading its weights.

    Pixel space (no VAE): the UNet denoises ``resolution``-pixel RGB images; its input is the noisy
    target (3 channels) concatenated with the reference image (3), as Zero-1-to-3 concatenates the
    reference latent. The schedule is Zero-1-to-3's (1000 steps, ``scaled_linear`` betas).
    ``prediction_type`` is what the UNet outputs: ``"epsilon"`` (Zero-1-to-3's noise) or ``"sample"``
    (the clean target, converted to noise for the solver), a deviation that makes the training loss at
    high noise levels a view-synthesis error, the signal the pose inversion needs.
    ``absolute_view_conditioning``: a second deviation. A linear head on the reference embedding
    regresses the reference's absolute view (trained on the renders' cameras), the relative pose is
    composed onto it, and the pose features the UNet's class embedding sees are those of the absolute
    target view, so the UNet learns "object x from view v" instead of the harder "view v from view u".
    """

    resolution: int = 32
    block_out_channels: tuple[int, ...] = (32, 64, 128)
    layers_per_block: int = 1
    attention_heads: int = 4
    resnet_time_scale_shift: str = "default"
    token_in_timestep_embedding: bool = False
    norm_num_groups: int = 8
    embedding_dim: int = 128
    encoder_patch_size: int = 4
    encoder_layers: int = 2
    encoder_heads: int = 4
    num_train_timesteps: int = 1000
    beta_start: float = 0.00085
    beta_end: float = 0.012
    beta_schedule: str = "scaled_linear"
    prediction_type: str = "sample"
    absolute_view_conditioning: bool = True
    reference_warp: bool = False
    warp_radius: float = 0.6

    def validate(self) -> DemoModelConfig:
        """Raise ValueError naming the first inconsistent field; return self."""
        if self.resolution % (2 ** (len(self.block_out_channels) - 1)) or self.resolution < 8:
            raise ValueError(f"resolution {self.resolution} must be >= 8 and divisible by the UNet's downsampling")
        if self.resolution % self.encoder_patch_size:
            raise ValueError(f"encoder_patch_size {self.encoder_patch_size} must divide resolution {self.resolution}")
        if any(c % self.norm_num_groups for c in self.block_out_channels):
            raise ValueError(f"norm_num_groups {self.norm_num_groups} must divide every block_out_channels entry")
        if self.resnet_time_scale_shift not in ("default", "scale_shift"):
            raise ValueError("resnet_time_scale_shift must be 'default' or 'scale_shift', "
                             f"got {self.resnet_time_scale_shift!r}")
        if self.embedding_dim % self.encoder_heads:
            raise ValueError(f"encoder_heads {self.encoder_heads} must divide embedding_dim {self.embedding_dim}")
        if not 0.0 < self.warp_radius <= 1.0:
            raise ValueError(f"warp_radius must be in (0, 1], got {self.warp_radius}")
        if self.prediction_type not in ("epsilon", "sample"):
            raise ValueError(f"prediction_type must be 'epsilon' or 'sample', got {self.prediction_type!r}")
        return self

    def unet_kwargs(self) -> dict:
        """Arguments of diffusers ``UNet2DConditionModel``: attention only at the lowest resolution."""
        levels = len(self.block_out_channels)
        return dict(
            sample_size=self.resolution,
            in_channels=6 + (WARP_CHANNELS if self.reference_warp else 0),
            out_channels=3,
            block_out_channels=tuple(self.block_out_channels),
            layers_per_block=self.layers_per_block,
            down_block_types=("DownBlock2D",) * (levels - 1) + ("CrossAttnDownBlock2D",),
            up_block_types=("CrossAttnUpBlock2D",) + ("UpBlock2D",) * (levels - 1),
            cross_attention_dim=self.embedding_dim,
            attention_head_dim=self.attention_heads,
            norm_num_groups=self.norm_num_groups,
            resnet_time_scale_shift=self.resnet_time_scale_shift,
            class_embed_type="projection",
            projection_class_embeddings_input_dim=self.class_embedding_dim,
        )

    @property
    def class_embedding_dim(self) -> int:
        """Input size of the UNet's projection class embedding: pose Fourier features (+ the cc_projection token)."""
        return FOURIER_DIM + (self.embedding_dim if self.token_in_timestep_embedding else 0)

    def encoder_config(self) -> CLIPVisionConfig:
        """A tiny transformers CLIP vision tower (trained from scratch) on ``resolution``-pixel images."""
        return CLIPVisionConfig(
            image_size=self.resolution,
            patch_size=self.encoder_patch_size,
            num_channels=3,
            hidden_size=self.embedding_dim,
            intermediate_size=2 * self.embedding_dim,
            num_hidden_layers=self.encoder_layers,
            num_attention_heads=self.encoder_heads,
            projection_dim=self.embedding_dim,
        )

    def save(self, path: Path) -> None:
        """Write the config as JSON."""
        Path(path).write_text(json.dumps(asdict(self), indent=2) + "\n")

    @classmethod
    def load(cls, path: Path) -> DemoModelConfig:
        """Read a JSON config; unknown keys are an error naming them."""
        data = json.loads(Path(path).read_text())
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"{path}: unknown demo-model config keys {unknown}")
        if "block_out_channels" in data:
            data["block_out_channels"] = tuple(data["block_out_channels"])
        return cls(**data).validate()
