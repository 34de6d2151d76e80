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


def episode_contrastive_loss(z_first: torch.Tensor, z_second: torch.Tensor, temperature: float = 0.1) -> torch.Tensor:
    """InfoNCE over 2n frame embeddings (n, d) x 2: frame i of `z_first` and frame i of `z_second` come from the
    same trajectory and must pick each other out among all 2n - 1 others (SimCLR's NT-Xent, cosine similarity)."""
    n = len(z_first)
    z = F.normalize(torch.cat([z_first, z_second]), dim=-1)
    sim = (z @ z.T / temperature).masked_fill(torch.eye(2 * n, dtype=torch.bool, device=z.device), float("-inf"))
    partner = torch.cat([torch.arange(n, 2 * n), torch.arange(n)]).to(z.device)
    return F.cross_entropy(sim, partner)
