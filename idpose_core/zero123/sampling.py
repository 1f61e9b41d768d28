"""Novel-view generation with Zero-1-to-3: DDIM with classifier-free guidance, to check a pose by eye."""
from __future__ import annotations

from typing import Any, Protocol

import torch
from diffusers import DDIMScheduler
from tqdm.auto import tqdm

from idpose_core.noise_predictor import Views


class ConditionedDenoiser(Protocol):
    """What the sampler needs of a Zero-1-to-3 model (``Zero123Predictor`` is one): its device and scheduler,
    the cross-attention token of an embedding and a pose, and one conditioned noise prediction."""

    device: torch.device
    modules: Any  # holds ``scheduler``

    def pose_tokens(self, image_embeds: torch.Tensor, pose: torch.Tensor) -> torch.Tensor: ...

    def predict_noise(self, noisy: torch.Tensor, ref_latents: torch.Tensor, t: torch.Tensor,
                      tokens: torch.Tensor) -> torch.Tensor: ...


@torch.no_grad()
def sample_view(predictor: ConditionedDenoiser, views: Views, ref: int, pose, steps: int = 50,
                guidance: float = 3.0, eta: float = 1.0, seed: int = 0) -> torch.Tensor:
    """The view at relative ``pose`` (3,) from view ``ref`` -> (3, H, W) in [-1, 1], float32 on the CPU.

    As the original sampler: DDIM (eta 1.0 by default) from pure noise; the unconditional branch
    gets a zero cross-attention token and a zero reference latent; eps = u + guidance (c - u).
    """
    if not 0 <= ref < len(views):
        raise ValueError(f"ref must index one of the {len(views)} views, got {ref}")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    device = predictor.device
    scheduler = DDIMScheduler.from_config(predictor.modules.scheduler.config)
    scheduler.set_timesteps(steps, device=device)
    generator = torch.Generator(device=device).manual_seed(seed)
    pose = torch.as_tensor(pose, dtype=torch.float32, device=device).reshape(1, 3)
    token = predictor.pose_tokens(views.conditioning["image_embeds"][ref : ref + 1], pose)
    ref_latent = views.conditioning["ref_latents"][ref : ref + 1]
    tokens = torch.cat([torch.zeros_like(token), token])
    ref_latents = torch.cat([torch.zeros_like(ref_latent), ref_latent])
    latent = torch.randn((1, *views.noise_shape), generator=generator, device=device) * scheduler.init_noise_sigma
    for t in tqdm(scheduler.timesteps, desc="sample_view (DDIM)", leave=False):
        noisy = scheduler.scale_model_input(latent, t).expand(2, -1, -1, -1)
        unconditional, conditional = predictor.predict_noise(noisy, ref_latents, t.expand(2), tokens).float().chunk(2)
        eps = unconditional + guidance * (conditional - unconditional)
        latent = scheduler.step(eps, t, latent, eta=eta, generator=generator).prev_sample
    vae = predictor.modules.vae
    image = vae.decode(latent / vae.config.scaling_factor).sample
    return image[0].clamp(-1, 1).float().cpu()
