"""The training objective of the latent space, paper Eq. 1-3: L = L_align + L_norm."""

from __future__ import annotations

import torch
import torch.nn.functional as F


def align_loss(phi_a: torch.Tensor, phi_b: torch.Tensor, psi: torch.Tensor) -> torch.Tensor:
    """Eq. 1, per sample: -log sigmoid(psi_l . (phi_B - phi_A))."""
    return -F.logsigmoid((psi * (phi_b - phi_a)).sum(dim=-1))


def norm_loss(phi_a: torch.Tensor, phi_b: torch.Tensor, psi: torch.Tensor, a: float, b: float) -> torch.Tensor:
    """Eq. 2, per sample: a * (max(|phi_A| - 1, 0) + max(|phi_B| - 1, 0)) + b * (|psi_l| - 1)^2.

    The paper prints the last term as ||psi_l - 1||^2; its text (and the authors' code) mean the norm of psi close to 1.
    """
    hinge = F.relu(phi_a.norm(dim=-1) - 1) + F.relu(phi_b.norm(dim=-1) - 1)
    return a * hinge + b * (psi.norm(dim=-1) - 1) ** 2


def latent_loss(
    phi_a: torch.Tensor, phi_b: torch.Tensor, psi: torch.Tensor, a: float, b: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Eq. 3 averaged over the batch: (total, align, norm)."""
    la = align_loss(phi_a, phi_b, psi).mean()
    ln = norm_loss(phi_a, phi_b, psi, a, b).mean()
    return la + ln, la, ln
