"""The networks of EgoExoMoCap (paper § Method), sized for CPU training.

Tensor layouts (row-major, batch first, T = 96 frames, N observer slots, K = 13 keypoints):

- EgoNet: ``ego [B,T,62]`` -> ``root_6d [B,T,6]``, ``body_6d [B,T,126]`` (window frame).
- Gate: ``gate_features [B,T,N,K,F]`` -> ``gate [B,T,N,K]`` in [0, 1].
- Fusion: ``ego [B,T,62]``, ``egonet [B,T,132]``, ``exo [B,T,N,K,7]`` (exo token layout v4:
  per keypoint and frame, the ray endpoint xyz in the wearer head frame, the offset xyz from
  EgoNet's coarse keypoint to its ray in the window frame, and the gate, 0 where there is no
  valid ray), ``observer_mask [B,T,N]`` (1 = present) -> ``root_6d [B,T,6]``,
  ``body_6d [B,T,126]``. The graph low-passes each keypoint's endpoints and offsets over time
  weighted by the gate (`gate_weighted_track_smoothing`), then scales them by the gate.

6D rotations are the first two *columns* of the rotation matrix, as in the Rust core.
Attention is written out with plain matmuls so the ONNX export is a small, portable op set
(MatMul, Softmax, LayerNormalization, Erf) that tract runs.
"""

import math

import torch
from torch import nn

EGO_DIM = 62
#: The ego feature layout these networks read (`EGO_FEATURE_LAYOUT_VERSION` in `egoexo-core`):
#: v2 adds per-frame wrist validity (slots 60, 61).
EGO_LAYOUT_VERSION = 2
POSE_DIM = 132
ROOT_DIM = 6
BODY_DIM = 126
K = 13
#: Numbers per keypoint in the exo input (`EXO_TOKEN_DIM`, layout v4, in `egoexo-infer`).
EXO_TOKEN_DIM = 7
EXO_TOKEN_LAYOUT_VERSION = 4
MASKED = -1.0e4


def gaussian_kernel_matrix(frames: int, sigma: float) -> torch.Tensor:
    """``W [frames, frames]``, ``W[t, s] = exp(-(t - s)^2 / (2 sigma^2))`` truncated at 3 sigma
    (unnormalised; `sigma` in frames, > 0)."""
    if not sigma > 0:
        raise ValueError(f"sigma must be > 0 frames, got {sigma}")
    t = torch.arange(frames, dtype=torch.float32)
    weights = torch.exp(-0.5 * ((t.unsqueeze(1) - t.unsqueeze(0)) / sigma) ** 2)
    return weights * (weights >= math.exp(-0.5 * 9.0) * (1 - 1e-6))


def gaussian_smoothing_matrix(frames: int, sigma: float) -> torch.Tensor:
    """``S [frames, frames]`` with ``S @ x`` a Gaussian low-pass over time (standard deviation
    `sigma` frames), each row renormalised over the frames inside the window so a constant
    sequence is unchanged up to its edges. ``sigma = 0`` gives the identity."""
    if sigma < 0:
        raise ValueError(f"sigma must be >= 0 frames, got {sigma}")
    if sigma == 0:
        return torch.eye(frames)
    weights = gaussian_kernel_matrix(frames, sigma)
    return weights / weights.sum(dim=1, keepdim=True)


# With `exo_fade`, an observer counts as present at a frame where its low-passed gates sum
# to more than this (a tenth of one keypoint's full weight).
FADE_PRESENT = 0.1


def gate_weighted_track_smoothing(kernel: torch.Tensor, values: torch.Tensor, gate: torch.Tensor) -> torch.Tensor:
    """Each track's gate-weighted Gaussian mean over time: ``values [B,T,N,K,C]`` and
    ``gate [B,T,N,K,1]`` (0 where there is no detection) -> ``[B,T,N,K,C]`` with, at frame t,
    ``sum_s W[t,s] g_s x_s / sum_s W[t,s] g_s`` (``kernel`` = W from `gaussian_kernel_matrix`).
    A detection the gate rejects (g = 0) leaves its neighbours' means as well as its own frame;
    with the gate at the validity mask it is the plain low-pass over the detected frames.
    Frames without a detection get their neighbours' mean (0 if none), which the fusion graph
    multiplies by their gate, 0: gaps stay empty (with `exo_fade`, by the faded gate instead)."""
    b, t, n, k, c = values.shape
    weighted = torch.cat([values * gate, gate], dim=-1).reshape(b, t, n * k * (c + 1))
    summed = (kernel @ weighted).reshape(b, t, n, k, c + 1)
    return summed[..., :c] / summed[..., c:].clamp(min=1e-6)


def faded_exo_tracks(kernel: torch.Tensor, rays: torch.Tensor, gate: torch.Tensor,
                     observer_mask: torch.Tensor) -> tuple:
    """The exo inputs faded in and out over time (`Fusion(exo_fade=True)`): ``rays
    [B,T,N,K,C]``, ``gate [B,T,N,K,1]`` (0 where there is no detection) and ``observer_mask
    [B,T,N]`` -> (the gate-weighted low-pass of the rays, `gate_weighted_track_smoothing`;
    the low-passed gate ``sum_s W[t,s] g_s / sum_s W[t,s]``; the observers present).

    Gates are zeroed where the observer is masked first, so a masked observer stays absent. A
    ray that appears or vanishes then ramps over about 2 sigma frames instead of stepping,
    frames without a detection between detections carry a faded-out estimate, and an observer
    counts as present wherever its low-passed gates sum to more than `FADE_PRESENT` — an
    observer missed for a frame or two no longer drops out of the spatial transformer."""
    b, t, n = observer_mask.shape
    gate = gate * observer_mask.reshape(b, t, n, 1, 1)
    rays = gate_weighted_track_smoothing(kernel, rays, gate)
    faded = (kernel @ gate.reshape(b, t, -1)).reshape(gate.shape) / kernel.sum(dim=1).reshape(1, t, 1, 1, 1)
    present = (faded.sum(dim=(-1, -2)) > FADE_PRESENT).to(faded.dtype)
    return rays, faded, present


def sinusoidal_encoding(length: int, dim: int) -> torch.Tensor:
    """The Transformer's fixed sinusoidal positional encoding, ``[length, dim]``."""
    position = torch.arange(length, dtype=torch.float32).unsqueeze(1)
    div = torch.exp(torch.arange(0, dim, 2, dtype=torch.float32) * (-math.log(10000.0) / dim))
    pe = torch.zeros(length, dim)
    pe[:, 0::2] = torch.sin(position * div)
    pe[:, 1::2] = torch.cos(position * div[: dim // 2])
    return pe


def mlp(inp: int, hidden: int, out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(inp, hidden), nn.GELU(), nn.Linear(hidden, out))


class MixerBlock(nn.Module):
    """One MLP-Mixer block: token mixing across time, then channel mixing (pre-norm)."""

    def __init__(self, frames: int, dim: int, token_hidden: int, channel_hidden: int):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim)
        self.token = mlp(frames, token_hidden, frames)
        self.norm2 = nn.LayerNorm(dim)
        self.channel = mlp(dim, channel_hidden, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x + self.token(self.norm1(x).transpose(1, 2)).transpose(1, 2)
        return x + self.channel(self.norm2(x))


class EgoNet(nn.Module):
    """Ego-only coarse pose (paper § Ego-Guided Wearer Localization)."""

    def __init__(self, frames: int = 96, hidden: int = 256):
        super().__init__()
        self.embed = nn.Linear(EGO_DIM, hidden)
        self.register_buffer("positions", sinusoidal_encoding(frames, hidden), persistent=False)
        self.mixer = MixerBlock(frames, hidden, hidden, 2 * hidden)
        self.root_head = mlp(hidden, hidden, ROOT_DIM)
        self.body_head = mlp(hidden, hidden, BODY_DIM)

    def forward(self, ego: torch.Tensor):
        x = self.mixer(self.embed(ego) + self.positions)
        return self.root_head(x), self.body_head(x)


class Gate(nn.Module):
    """Per-joint confidences from the core's gate features (the paper's ScoreNet reads a DINO
    CLS token instead; none can ship here). Two layers, sigmoid, over all K joints of one
    observer-frame so the gate can use the whole body's agreement pattern."""

    def __init__(self, features: int = 5, hidden: int = 128):
        super().__init__()
        self.net = mlp(K * features, hidden, K)

    def forward(self, gate_features: torch.Tensor) -> torch.Tensor:
        b, t, n, k, f = gate_features.shape
        logits = self.net(gate_features.reshape(b, t, n, k * f))
        return torch.sigmoid(logits)


class Attention(nn.Module):
    def __init__(self, dim: int, heads: int):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.out = nn.Linear(dim, dim)
        # [dim, heads]: 1 where a channel belongs to a head. Sums per-channel products into
        # per-head scores and spreads per-head weights back over the channels (`first_query_only`).
        self.register_buffer("head_channels", torch.repeat_interleave(torch.eye(heads), dim // heads, dim=0),
                             persistent=False)

    def forward(self, x: torch.Tensor, key_bias: torch.Tensor | None, first_query_only: bool = False) -> torch.Tensor:
        """``x [B,S,D]`` -> ``[B,S,D]``, or ``[B,1,D]`` (the first token's output only) with
        `first_query_only`. With one token (S = 1) the softmax over one key is exactly 1, so
        the output is the value's projection and no scores are computed."""
        b, s, d = x.shape
        h = self.heads
        if s == 1:
            value = nn.functional.linear(x, self.qkv.weight[2 * d:], self.qkv.bias[2 * d:])
            return self.out(value)
        if first_query_only:
            # One query against a few keys (the spatial transformer's ego token against the
            # observers): per-head dot products as a channel-wise product summed per head by
            # one matrix product, instead of B x heads tiny products.
            q = nn.functional.linear(x[:, :1], self.qkv.weight[:d], self.qkv.bias[:d])
            kv = nn.functional.linear(x, self.qkv.weight[d:], self.qkv.bias[d:])
            k, v = kv[..., :d], kv[..., d:]
            # [B, heads, S]: keys last, so the softmax and the sums run over the last axis.
            scores = (self.head_channels.T @ (q * k).transpose(1, 2)) * (1.0 / math.sqrt(d // h))
            if key_bias is not None:
                scores = scores + key_bias[:, None, :]
            attn = torch.softmax(scores, dim=-1)
            # Each channel's head weight per key [B, D, S], times the values, summed over keys.
            return self.out(((self.head_channels @ attn) * v.transpose(1, 2)).sum(dim=-1).unsqueeze(1))
        q, k, v = self.qkv(x).reshape(b, s, 3, h, d // h).permute(2, 0, 3, 1, 4)
        scores = torch.matmul(q, k.transpose(-1, -2)) * (1.0 / math.sqrt(d // h))
        if key_bias is not None:
            scores = scores + key_bias[:, None, None, :]
        attn = torch.softmax(scores, dim=-1)
        return self.out(torch.matmul(attn, v).permute(0, 2, 1, 3).reshape(b, s, d))


class EncoderLayer(nn.Module):
    """Pre-norm Transformer encoder layer."""

    def __init__(self, dim: int, heads: int, ff: int, dropout: float):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim)
        self.attn = Attention(dim, heads)
        self.norm2 = nn.LayerNorm(dim)
        self.ff = mlp(dim, ff, dim)
        self.drop = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, key_bias: torch.Tensor | None = None,
                first_query_only: bool = False) -> torch.Tensor:
        """``x [B,S,D]`` -> ``[B,S,D]``; with `first_query_only` only the first token's output,
        ``[B,1,D]``, the same numbers as ``forward(x)[:, :1]`` without computing the others'
        queries, output projections and feed-forwards."""
        attended = self.attn(self.norm1(x), key_bias, first_query_only)
        x = (x[:, :1] if first_query_only else x) + self.drop(attended)
        return x + self.drop(self.ff(self.norm2(x)))


class Fusion(nn.Module):
    """Ego/exo tokens -> spatial transformer over [ego, exo_1..exo_N] (ego output kept) ->
    temporal transformer with learned positions -> root and body 6D. Predicts a residual on
    EgoNet's coarse pose, so with every observer masked it refines the ego-only estimate.

    `output_smoothing` > 0 ends the network with a fixed Gaussian low-pass over the window's
    frames (standard deviation in frames; `gaussian_smoothing_matrix`) on the 6D outputs, part
    of the trained and exported graph: the transformer's frame-to-frame flicker is filtered
    out and the losses see the filtered motion.

    `exo_smoothing` > 0 low-passes each keypoint's ray endpoints and offsets over time, weighted
    by the gate (`gate_weighted_track_smoothing`, standard deviation in frames), before they are
    scaled by the gate: detector noise is independent from frame to frame, the motion is not.
    `exo_fade` (with `exo_smoothing`) also low-passes the gate itself and derives the observers'
    presence from it (`faded_exo_tracks`), so rays and observers fade in and out instead of
    switching on and off."""

    def __init__(self, frames: int = 96, hidden: int = 128, heads: int = 4, spatial_layers: int = 2,
                 temporal_layers: int = 3, dropout: float = 0.1, exo_embed: str = "linear",
                 output_smoothing: float = 0.0, exo_smoothing: float = 0.0, exo_fade: bool = False):
        super().__init__()
        self.exo_fade = exo_fade
        if exo_fade and not exo_smoothing > 0:
            raise ValueError("exo_fade needs exo_smoothing > 0")
        self.output_smoothing = output_smoothing
        self.register_buffer("smoothing", gaussian_smoothing_matrix(frames, output_smoothing), persistent=False)
        self.exo_smoothing = exo_smoothing
        if exo_smoothing > 0:
            self.register_buffer("exo_kernel", gaussian_kernel_matrix(frames, exo_smoothing), persistent=False)
        self.ego_token = nn.Linear(EGO_DIM + POSE_DIM, hidden)
        # The paper projects the rays linearly; "mlp" adds a hidden layer (same width) so each
        # observer's 13 rays are combined non-linearly before the spatial transformer.
        if exo_embed == "linear":
            self.exo_token = nn.Linear(K * EXO_TOKEN_DIM, hidden)
        elif exo_embed == "mlp":
            self.exo_token = mlp(K * EXO_TOKEN_DIM, hidden, hidden)
        else:
            raise ValueError(f"exo_embed must be 'linear' or 'mlp', got {exo_embed!r}")
        self.token_type = nn.Parameter(torch.zeros(2, hidden))
        self.spatial = nn.ModuleList([EncoderLayer(hidden, heads, 2 * hidden, dropout) for _ in range(spatial_layers)])
        self.temporal_positions = nn.Parameter(torch.zeros(frames, hidden))
        nn.init.normal_(self.temporal_positions, std=0.02)
        self.temporal = nn.ModuleList([EncoderLayer(hidden, heads, 2 * hidden, dropout) for _ in range(temporal_layers)])
        self.norm = nn.LayerNorm(hidden)
        self.root_head = mlp(hidden, hidden, ROOT_DIM)
        self.body_head = mlp(hidden, hidden, BODY_DIM)

    def forward(self, ego, egonet, exo, observer_mask):
        b, t, n = observer_mask.shape
        ego_tok = self.ego_token(torch.cat([ego, egonet], dim=-1)) + self.token_type[0]
        rays, gate = exo[..., :EXO_TOKEN_DIM - 1], exo[..., EXO_TOKEN_DIM - 1:]
        if self.exo_fade:
            rays, gate, observer_mask = faded_exo_tracks(self.exo_kernel, rays, gate, observer_mask)
        elif self.exo_smoothing > 0:
            rays = gate_weighted_track_smoothing(self.exo_kernel, rays, gate)
        exo = torch.cat([rays * gate, gate], dim=-1)
        exo_tok = self.exo_token(exo.reshape(b, t, n, K * EXO_TOKEN_DIM)) + self.token_type[1]
        tokens = torch.cat([ego_tok.unsqueeze(2), exo_tok], dim=2).reshape(b * t, n + 1, -1)
        present = torch.cat([torch.ones_like(observer_mask[..., :1]), observer_mask], dim=-1).reshape(b * t, n + 1)
        key_bias = (1.0 - present) * MASKED
        # Only the ego token leaves the spatial transformer, so its last layer computes the ego
        # token's output alone (the same numbers; the exo tokens still serve as keys/values).
        for i, layer in enumerate(self.spatial):
            tokens = layer(tokens, key_bias, first_query_only=i + 1 == len(self.spatial))
        return self.temporal_readout(tokens[:, 0].reshape(b, t, -1), egonet)

    def ego_only(self, ego, egonet):
        """`forward` with every observer masked, without the observers: ``ego [B,T,62]``,
        ``egonet [B,T,132]`` -> ``root_6d``, ``body_6d``. A masked observer's key carries the
        bias `MASKED`, whose softmax weight underflows to exactly 0 in float32, so the ego token
        attends to itself alone; the spatial transformer then runs on the ego token by itself
        (`Attention` with one token) — the same numbers up to rounding, for a fraction of the
        work."""
        b, t, _ = ego.shape
        tokens = (self.ego_token(torch.cat([ego, egonet], dim=-1)) + self.token_type[0]).reshape(b * t, 1, -1)
        for layer in self.spatial:
            tokens = layer(tokens)
        return self.temporal_readout(tokens.reshape(b, t, -1), egonet)

    def temporal_readout(self, x, egonet):
        """The ego tokens after the spatial transformer ``[B,T,hidden]`` -> temporal
        transformer -> root and body 6D (residuals on EgoNet's, optionally low-passed)."""
        x = x + self.temporal_positions
        for layer in self.temporal:
            x = layer(x)
        x = self.norm(x)
        root = egonet[..., :ROOT_DIM] + self.root_head(x)
        body = egonet[..., ROOT_DIM:] + self.body_head(x)
        if self.output_smoothing > 0:
            root, body = self.smoothing @ root, self.smoothing @ body
        return root, body


class FusionEgoOnly(nn.Module):
    """The fusion network with every observer masked as its own graph (`Fusion.ego_only`):
    ``ego``, ``egonet`` -> ``root_6d``, ``body_6d``; what the engine runs for the ego-only
    method and for live sessions without observers."""

    def __init__(self, fusion: Fusion):
        super().__init__()
        self.fusion = fusion

    def forward(self, ego, egonet):
        return self.fusion.ego_only(ego, egonet)
