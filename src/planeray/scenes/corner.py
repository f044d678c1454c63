"""A concave 90-degree corner: diffuse interreflection with a steep, one-sided delay profile.

Model
-----
Two Lambertian faces meet at a horizontal crease at camera row ``round(crease * H)``:
face A (a wall, every row above the crease) and face B (a floor, every row
below).  Rows are epipolar planes, so projector row ``v`` lights the line of the
face that camera row ``v`` sees.  Distance from the crease along a face is
``|y - y_c| * mm_per_row`` with a different ``mm_per_row`` per face (the faces are
foreshortened differently as seen from the projector-camera).

One-bounce interreflection uses the exact 2D (infinite-strip) form factor of
two perpendicular half-planes: a point of face A at distance ``a`` from the
crease receives from a strip of face B at distance ``b``::

    dF = a b / (2 (a^2 + b^2)^(3/2)) db,    int_b0^b1 dF = 1/2 (a / sqrt(a^2 + b0^2) - a / sqrt(a^2 + b1^2))

(and symmetrically for B receiving from A).  The closed form is integrated
exactly over every offset bin ``[p_t + u - 1/2, p_t + u + 1/2)`` of projector rows,
and averaged over sub-samples of the receiving camera row's footprint.  With the
projector's irradiance per row equal on both faces (a lit face radiates
``rho E``; direct light of a white face is ``T = 1``)::

    T_ind[t, s, u] = rho_A(t, s) rho_B(v, s) F_t(u)        (A receives from B: u > 0 only)
    T_ind[t, s, u] = rho_B(t, s) rho_A(v, s) F_t(u)        (B receives from A: u < 0 only)

so the delay profile is one-sided and steepest next to the crease, where half
of the hemisphere is the other face.  The direct term is the albedo spread over
the camera row's footprint.

Assumptions and approximations
------------------------------
* Along the crease the faces are infinite (continued beyond the image by
  mirroring the texture).  The light of a strip arrives from a spread of columns:
  integrating the 3D point-to-area form factor ``a b / (pi (x^2 + c^2)^2)`` over
  ``x`` gives the strip form factor times the kernel ``2 c^3 / (pi (x^2+c^2)^2)``
  with ``c^2 = a^2 + b^2``, so ``rho_B(v, s)`` above is the source row's albedo
  blurred along the row by that kernel (exact per pixel; ``c`` quantized to
  scales 1.25x apart).  Occlusion is ignored.
* Offsets beyond the dense band (``|u| > band_rows``, outside the paper's
  +-114-row sweep support) are kept as sparse entries lumped over
  ``far_group_rows``-row groups (default 8 camera rows, at most 16 groups a
  side) at their weighted centre (total energy is exact, their position within
  a group is approximate); ``far_group_rows = 0`` drops them.
* ``bounces = 2`` adds the second bounce A -> B -> A (and B -> A -> B), with the
  intermediate face discretized on camera rows (same-column albedos, no
  along-crease blur).  It lands on the receiver's own
  face, so it breaks the one-sided profile; it is off by default and small
  (``< rho^3 / 4``).

References
----------
.. [1] M. F. Cohen, J. R. Wallace, "Radiosity and Realistic Image Synthesis",
   1993 (form factors between perpendicular strips / 2D form factors).
.. [2] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport", TVCG
   2019, Fig. 9 ("diffuse interreflection in the near corner has a steeper profile").
"""

from __future__ import annotations

import numpy as np

from ..timing import RowGeometry
from ..transport import SparseEntries, Transport
from ._textures import floor_tiles, smooth_noise, wallpaper
from .base import DEFAULT_BAND_ROWS, DEFAULT_MM_PER_ROW, Scene, footprint_kernel, register_scene, scene_offsets

__all__ = ["build", "strip_form_factor"]


def strip_form_factor(d, lo, hi):
    """Form factor from a point at distance ``d`` from the crease to the strip ``[lo, hi]``
    of the perpendicular face (all in mm, ``0 <= lo <= hi``): ``1/2 (d/sqrt(d^2+lo^2) - d/sqrt(d^2+hi^2))``."""
    d = np.asarray(d, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        f_lo = np.where(d > 0, d / np.sqrt(d * d + lo * lo), np.where(lo > 0, 0.0, 1.0))
        f_hi = np.where(d > 0, d / np.sqrt(d * d + hi * hi), np.where(hi > 0, 0.0, 1.0))
    return 0.5 * (f_lo - f_hi)


def _profiles(geometry, x_c, mm_a, mm_b, offsets, n_sub):
    """Form factor per (camera row, offset bin), averaged over the row footprint.

    Returns ``F`` (H, U) and the face (``True`` for A) of each camera row.
    """
    H, P, rpc = geometry.camera_rows, geometry.projector_rows, geometry.rows_per_camera_row
    p_t = geometry.projector_row_of(np.arange(H))
    frac = (np.arange(n_sub) + 0.5) / n_sub
    y = (np.arange(H)[:, None] + frac[None, :]) * rpc - 0.5  # (H, n) receiving points, proj. coords
    lo = p_t[:, None] + offsets[None, :] - 0.5  # (H, U) bin edges
    hi = lo + 1.0
    top, bottom = -0.5, P - 0.5
    on_a = y < x_c
    # A receives from B (rows below the crease).
    b0 = (np.clip(lo, x_c, bottom) - x_c) * mm_b
    b1 = (np.clip(hi, x_c, bottom) - x_c) * mm_b
    a = (x_c - y) * mm_a
    FA = strip_form_factor(a[:, :, None], b0[:, None, :], b1[:, None, :])
    # B receives from A (rows above the crease).
    a0 = (x_c - np.clip(hi, top, x_c)) * mm_a
    a1 = (x_c - np.clip(lo, top, x_c)) * mm_a
    b = (y - x_c) * mm_b
    FB = strip_form_factor(b[:, :, None], a0[:, None, :], a1[:, None, :])
    F = np.where(on_a[:, :, None], FA, FB).mean(axis=1)
    return F, on_a.mean(axis=1) > 0.5


def _second_bounce(geometry, x_c, mm_a, mm_b, offsets, albedo, crease_row, n_sub):
    """A -> B -> A and B -> A -> B transport on the dense offsets (float32, (H, W, U)).

    The intermediate face is discretized on its camera rows (centre point, own albedo).
    """
    H, W = albedo.shape
    P, rpc = geometry.projector_rows, geometry.rows_per_camera_row
    out = np.zeros((H, W, offsets.size), np.float32)
    rows = np.arange(H)
    p_t = geometry.projector_row_of(rows)
    frac = (np.arange(n_sub) + 0.5) / n_sub
    y = (rows[:, None] + frac[None, :]) * rpc - 0.5
    edges = np.arange(H + 1) * rpc - 0.5  # camera-row edges in projector coordinates
    lo = p_t[:, None] + offsets[None, :] - 0.5
    hi = lo + 1.0
    for recv_a in (True, False):
        recv = rows < crease_row if recv_a else rows >= crease_row
        mid = ~recv  # intermediate face rows
        mm_r, mm_m = (mm_a, mm_b) if recv_a else (mm_b, mm_a)
        dist = lambda z: np.abs(z - x_c)  # noqa: E731  (projector rows from the crease)
        # Receiver points -> intermediate rows (exact over each intermediate camera row).
        m_lo, m_hi = edges[:-1][mid], edges[1:][mid]
        m_d0 = np.minimum(dist(m_lo), dist(m_hi)) * mm_m
        m_d1 = np.maximum(dist(m_lo), dist(m_hi)) * mm_m
        F1 = strip_form_factor(dist(y[recv])[:, :, None] * mm_r, m_d0[None, None, :], m_d1[None, None, :]).mean(axis=1)
        # Intermediate centres -> source bins on the receiver's face.
        if recv_a:
            s0, s1 = np.clip(hi[recv], -0.5, x_c), np.clip(lo[recv], -0.5, x_c)
        else:
            s0, s1 = np.clip(lo[recv], x_c, P - 0.5), np.clip(hi[recv], x_c, P - 0.5)
        src_d0, src_d1 = dist(s0) * mm_r, dist(s1) * mm_r  # (R, U)
        m_c = dist(0.5 * (m_lo + m_hi)) * mm_m  # (M,)
        F2 = strip_form_factor(m_c[None, None, :], src_d0[:, :, None], src_d1[:, :, None])  # (R, U, M)
        G = F2 * F1[:, None, :]  # (R, U, M)
        via = np.matmul(G, albedo[mid].astype(float)[None, :, :])  # (R, U, W)
        src_row = np.clip(np.floor((p_t[recv][:, None] + offsets[None, :] + 0.5) / rpc).astype(int), 0, H - 1)
        rho_src = albedo[src_row]  # (R, U, W)
        out[recv] = (albedo[recv][:, None, :] * via * rho_src).transpose(0, 2, 1)
    return out


def _strip_kernel_stack(albedo, scales_px):
    """``albedo`` blurred along rows by the along-crease kernel of each scale ``c`` (pixels).

    A point at distance ``a`` from the crease receives from the element ``(x, b)``
    of the other face with ``dF = a b / (pi (x^2 + c^2)^2) dx db``, ``c^2 = a^2 + b^2``;
    integrating over ``x`` gives the strip form factor times the normalized kernel
    ``2 c^3 / (pi (x^2 + c^2)^2)``, integrated exactly over each pixel.  The faces are
    continued beyond the image by mirroring.  Returns ``(S, H, W)``.
    """
    H, W = albedo.shape
    J = W  # kernel half-width in pixels (mirrored rows repeat beyond that)
    x = np.arange(-J, J + 1, dtype=float)
    padded = np.pad(albedo.astype(float), ((0, 0), (J, J)), mode="symmetric")
    n = padded.shape[1] + 2 * J + 1
    spec = np.fft.rfft(padded, n=n, axis=1)
    out = np.empty((len(scales_px), H, W))
    for i, c in enumerate(scales_px):
        if c < 0.2:
            out[i] = albedo
            continue
        cdf = lambda z, c=c: np.arctan(z / c) + c * z / (z * z + c * c)  # noqa: E731  (x pi, minus pi/2)
        k = cdf(x + 0.5) - cdf(x - 0.5)
        k /= k.sum()
        full = np.fft.irfft(spec * np.fft.rfft(k, n=n), n=n, axis=1)
        out[i] = full[:, 2 * J : 2 * J + W]
    return out


@register_scene("corner", "concave corner: diffuse interreflection (steep one-sided delay profile)")
def build(
    shape,
    projector_rows,
    seed,
    crease: float = 0.5,
    mm_per_row_a: float = DEFAULT_MM_PER_ROW,
    mm_per_row_b: float = 1.5 * DEFAULT_MM_PER_ROW,
    bounces: int = 1,
    band_rows: int = DEFAULT_BAND_ROWS,
    far_group_rows: int | None = None,
    mm_per_column: float | None = None,
    textured: bool = True,
    label_support_rows: int = 114,
    label_fraction: float = 0.1,
):
    """Build the scene.

    Parameters
    ----------
    crease : float
        Position of the crease as a fraction of the image height (rounded to a camera-row boundary).
    mm_per_row_a, mm_per_row_b : float
        Distance along face A (above) / face B (below) per projector row, mm.
    bounces : int
        1 (default, one-sided profiles) or 2 (adds A -> B -> A and B -> A -> B).
    band_rows : int
        Half-width of the dense offset band.
    far_group_rows : int, optional
        Offsets beyond the band are lumped over groups of this many rows into sparse
        entries (0: dropped; default: 8 camera rows, or more so that each side has at
        most 16 groups).
    mm_per_column : float, optional
        Width of a pixel column on both faces, mm (default: a camera row's height on face A).
    textured : bool
        Textured albedos (default) or uniform faces (0.65 above, 0.55 below) for validation.
    label_support_rows, label_fraction : float
        A pixel is labelled ``diffuse_interreflection`` when its indirect light within
        ``|u| <= label_support_rows`` (the paper sweep's support) exceeds
        ``label_fraction`` of its direct light.
    """
    if bounces not in (1, 2):
        raise ValueError(f"bounces must be 1 or 2, got {bounces}")
    H, W = shape
    rng = np.random.default_rng(seed)
    geometry = RowGeometry(H, projector_rows)
    P, rpc = geometry.projector_rows, geometry.rows_per_camera_row
    crease_row = int(np.clip(round(crease * H), 1, H - 1))
    x_c = crease_row * rpc - 0.5  # crease in continuous projector coordinates
    band = max(int(band_rows), int(np.ceil(rpc)) + 1)
    offsets = scene_offsets(band)

    if textured:
        wall = wallpaper(shape, rng, mean=0.65, amplitude=0.12)
        floor = floor_tiles(shape, rng, tiles=6, mean=0.55, spread=0.15, grout=0.2)
        albedo = np.where(np.arange(H)[:, None] < crease_row, wall, floor)
        albedo = albedo * (1.0 + smooth_noise(shape, rng, H / 8.0, 0.03))
    else:
        albedo = np.where(np.arange(H)[:, None] < crease_row, 0.65, 0.55) * np.ones(shape)
    albedo = np.clip(albedo, 0.02, 0.95).astype(np.float32)

    # Form factors over every offset that can reach the other face.
    reach = max(P, band)
    full = np.arange(-reach, reach + 1)
    n_sub = 4 * int(np.ceil(rpc))
    F, _ = _profiles(geometry, x_c, mm_per_row_a, mm_per_row_b, full, n_sub)  # (H, 2P+1)
    p_t = geometry.projector_row_of(np.arange(H))
    src_row = np.clip(np.floor((p_t[:, None] + full[None, :] + 0.5) / rpc).astype(int), 0, H - 1)  # (H, 2P+1)

    # Along-crease spread: the source strip's albedo blurred at the scale c = sqrt(a^2 + b^2).
    mm_col = mm_per_column if mm_per_column is not None else rpc * mm_per_row_a
    src = p_t[:, None] + full[None, :]
    d_recv = np.where(p_t < x_c, (x_c - p_t) * mm_per_row_a, (p_t - x_c) * mm_per_row_b)[:, None]
    d_src = np.where(src < x_c, (x_c - src) * mm_per_row_a, (src - x_c) * mm_per_row_b)
    c_px = np.hypot(d_recv, d_src) / mm_col
    c_lo = max(0.2, float(c_px.min()))
    n_scales = int(np.ceil(np.log(max(c_px.max(), c_lo * 1.01) / c_lo) / np.log(1.25))) + 1
    scales = c_lo * 1.25 ** np.arange(n_scales)
    stack = _strip_kernel_stack(albedo, scales).astype(np.float32)
    scale_idx = np.clip(np.rint(np.log(np.maximum(c_px, c_lo) / c_lo) / np.log(1.25)).astype(int), 0, n_scales - 1)

    inb = (full >= offsets[0]) & (full <= offsets[-1])
    Fd = F[:, inb].astype(np.float32)
    rho_src = stack[scale_idx[:, inb], src_row[:, inb]]  # (H, U, W)
    indirect = (albedo[:, :, None] * (Fd[:, :, None] * rho_src).transpose(0, 2, 1)).astype(np.float32)
    if bounces == 2:
        indirect += _second_bounce(geometry, x_c, mm_per_row_a, mm_per_row_b, offsets, albedo, crease_row, n_sub)
    foot = footprint_kernel(offsets, rpc).astype(np.float32)
    dense = albedo[:, :, None] * foot[None, None, :] + indirect

    # Far tail: sparse entries lumped over groups of offsets.
    sparse = SparseEntries.empty()
    far = ~inb
    if far_group_rows is None:
        far_group_rows = max(8 * int(np.ceil(rpc)), int(np.ceil((reach - band) / 16)))
    if far_group_rows > 0 and np.any(F[:, far] > 0):
        g = int(far_group_rows)
        far_off = full[far]
        group = np.where(far_off > 0, (far_off - offsets[-1] - 1) // g, -((offsets[0] - 1 - far_off) // g) - 1)
        groups = np.unique(group)
        rows_l, cols_l, offs_l, vals_l = [], [], [], []
        for gi in groups:  # a few dozen groups, each vectorized over pixels
            sel = np.flatnonzero(far)[group == gi]
            w = F[:, sel]  # (H, n)
            tot = w.sum(axis=1)
            rows_nz = np.flatnonzero(tot > 0)
            if rows_nz.size == 0:
                continue
            centre = np.rint((w[rows_nz] * full[sel][None, :]).sum(axis=1) / tot[rows_nz]).astype(int)
            rho_far = stack[scale_idx[rows_nz][:, sel], src_row[rows_nz][:, sel]]
            val = np.einsum("rn,rnw->rw", w[rows_nz], rho_far) * albedo[rows_nz]
            rr, cc = np.meshgrid(rows_nz, np.arange(W), indexing="ij")
            rows_l.append(rr.ravel())
            cols_l.append(cc.ravel())
            offs_l.append(np.repeat(centre, W))
            vals_l.append(val.ravel())
        if rows_l:
            sparse = SparseEntries(
                np.concatenate(rows_l), np.concatenate(cols_l), np.concatenate(offs_l), np.concatenate(vals_l)
            )

    transport = Transport(dense, offsets, geometry, sparse)
    support = np.abs(offsets) <= label_support_rows
    near = indirect[:, :, support].sum(axis=2)
    labels = np.where(near > label_fraction * albedo, 3, 1).astype(np.uint8)
    params = {
        "crease": float(crease),
        "crease_row": crease_row,
        "mm_per_row_a": float(mm_per_row_a),
        "mm_per_row_b": float(mm_per_row_b),
        "bounces": int(bounces),
        "band_rows": int(band_rows),
        "far_group_rows": int(far_group_rows),
        "mm_per_column": float(mm_col),
        "textured": bool(textured),
        "label_support_rows": int(label_support_rows),
        "label_fraction": float(label_fraction),
    }
    return Scene("corner", transport, albedo.copy(), albedo.copy(), labels, params)
