"""Collector (b): per-bin sample statistics gathered inside the integrator (seed Alg. 4).

docs/methods/statistical.md §11.1-11.2, mode B. A subclass of mitransient's ``transient_path``
integrator (:class:`TransientPathStats`, plugin ``transient_path_stats``) that, instead of
adding each path contribution to the film histogram, keeps a small running state per path:

* a few *slots*, each a (bin, running sum) pair held in registers of the symbolic loop. A
  contribution (an emitter hit or a next-event estimate) whose bin is already in a slot is added
  to that slot's running sum; a contribution to a new bin opens a new slot. Next-event estimation
  makes the bin order along a path non-monotone (``OPL + ds.dist`` can go back), so a path may
  leave a bin and come back: the slot of that bin is simply found again and its sum continued,
  so every path yields exactly one sample per bin it touches (the spec's pitfall, §11.2).
* A slot is *flushed* at the end of the path: its float32 sum is transformed and scattered
  into float64 power sums S1, S2, S3 and the ``non_zero`` counts
  (:class:`~dbench.datasets.transient.voxel_sums.VoxelSums`: packet writes into per-thread
  copies on the LLVM backend where they fit, atomics otherwise) and a plain sum (only when the
  transform is not the identity, where S1 is the plain sum). Only the bins a path touches are
  scattered; bins a path never reaches are the zero-fill samples g(0), which add exactly 0 to
  the shifted sums (K = g(0)).
* ``slots = 2·max_depth`` (the default) can never overflow: a path has at most one emitter hit
  and one next-event estimate per vertex. With fewer slots, a slot is flushed as soon as the
  path's base optical path length has passed its bin (every later contribution has an OPL ≥ the
  current vertex's OPL, so the bin is final) and its slot is reused; a contribution that still
  finds every slot busy forces the oldest slot out early, counted in ``n_overflow`` (the
  statistics are exact if and only if ``n_overflow == 0``). ``slots = 1`` is the seed's Alg. 4
  as printed (flush whenever the bin changes), which double-counts re-entered bins. Measured:
  the full slot set is also the fastest (in-loop flushes cost more than the extra registers).

Memory: the statistics state is, per voxel and channel, 32 B in the packet layout (S1, S2, S3, N
float64) or 24 B + 8/3 B in the compact one (three float64 sums and 21 bits of a uint64 per
voxel), + 8 B of plain sum when the transform is not the identity, whatever the spp; a path's
state is 2 × slots registers of the symbolic loop, never stored per sample
(:meth:`StatsCollector.nbytes`).

The float32 running sums are added in path order, exactly as the film histogram adds them in a
1-spp pass, and the transform and power sums run in float64 with the same operations as the host
side :class:`~dbench.datasets.stats.PowerSums`, so for the same seeds (1-spp passes) the result is
bit-for-bit that of collector (a) (tests/datasets/test_transient.py). Rendering all spp in one call gives
the same statistics up to the order of the float64 atomic additions.

Only primal rendering is supported (no AD). The slot logic itself lives in
:mod:`dbench.datasets.transient.slots`, shared with the participating-media collector
(:mod:`dbench.datasets.transient.collector_media`, ``transient_prbvolpath``).

Example:
    >>> from dbench.datasets.transient.collector import StatsCollector   # doctest: +SKIP
    >>> col = StatsCollector(scene, transform="identity", max_depth=8)   # doctest: +SKIP
    >>> col.render(spp=64, seed=0)                                       # doctest: +SKIP
    >>> color, stats, non_zero = col.result()                            # doctest: +SKIP
"""
from __future__ import annotations

import time
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from ..mitsuba_env import mitsuba, require_llvm
from ...data import TRANSFORMS, check_transform
from ..stats import stats_from_power_sums, transform_of_zero, variance_of_mean
from .slots import with_slots
from . import stored_rows
from .voxel_sums import VoxelSums, dr_nbytes, host_array as _host

PLUGIN = "transient_path_stats"
_REGISTERED: dict[str, Any] = {}


def _define():
    """Define and register the integrator class (needs the variant set and mitransient)."""
    if "cls" in _REGISTERED:
        return _REGISTERED["cls"]
    require_llvm("the in-integrator transient statistics collector")
    mitsuba()
    import mitransient  # noqa: F401  (registers transient_path, the film)
    from mitransient.integrators.transientpath import TransientPath
    from mitsuba.ad.integrators.common import mis_weight

    # @dr.syntax recompiles sample() against the module globals, not this closure
    globals()["mis_weight"] = mis_weight

    class TransientPathStats(with_slots(TransientPath)):
        """``transient_path`` with per-path, per-bin running sums flushed into power sums.

        Properties: those of ``transient_path`` plus ``slots`` (int, 0 = 2·max_depth).
        Attach a :class:`StatsCollector` (``integrator.collector = c``) before rendering.
        A path adds at most one emitter hit and one next-event estimate per loop iteration
        (max_depth iterations), so 2·max_depth slots never overflow (no guard).
        """

        def __init__(self, props):
            super().__init__(props)
            self._init_slots(props, PLUGIN)

        @dr.syntax
        def sample(self, mode, scene, sampler, ray, β, δL, state_in, active, add_transient,
                   gather_derivatives_at_distance=None, **kwargs):
            if mode != dr.ADMode.Primal:
                raise NotImplementedError("transient_path_stats renders primal images only")
            col, voxel0, pixel_ok, ray_weight, st = self._open(PLUGIN)

            bsdf_ctx = mi.BSDFContext()
            ray = mi.Ray3f(dr.detach(ray))
            depth = mi.UInt32(0)
            L = mi.Spectrum(0)
            η = mi.Float(1)
            active = mi.Bool(active)
            distance = mi.Float(0.0)
            prev_si = dr.zeros(mi.SurfaceInteraction3f)
            prev_bsdf_pdf = mi.Float(1.0)
            prev_bsdf_delta = mi.Bool(True)

            if self.camera_unwarp:
                si0 = scene.ray_intersect(mi.Ray3f(ray), ray_flags=mi.RayFlags.All,
                                          coherent=mi.Mask(True))
                distance[si0.is_valid()] = -si0.t

            while dr.hint(active, max_iterations=self.max_depth,
                          label="Transient Path Stats"):
                active_next = mi.Bool(active)
                si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=(depth == 0))
                distance += dr.select(active, si.t, 0.0) * η
                bsdf = si.bsdf(ray)

                # ---------------------- Direct emission ----------------------
                if dr.hint(self.hide_emitters, mode='scalar'):
                    active_next &= ~((depth == 0) & ~si.is_valid())
                ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
                mis = mis_weight(prev_bsdf_pdf,
                                 scene.pdf_emitter_direction(prev_si, ds, ~prev_bsdf_delta))
                Le = β * mi.Spectrum(mis) * dr.select(self.discard_direct_light, 0,
                                                     ds.emitter.eval(si, active_next))

                # with fewer slots than contributions, free the slots of bins this vertex's
                # OPL has passed (no-op with the full slot set)
                st = self._release(col, voxel0, st, distance, active & pixel_ok)
                st = self._add(col, voxel0, st, distance, Le * ray_weight, active & pixel_ok)

                # ---------------------- Emitter sampling ----------------------
                active_next &= (depth + 1 < self.max_depth) & si.is_valid()
                active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True,
                                                               active_em)
                active_em &= (ds.pdf != 0.0)
                wo = si.to_local(ds.d)
                bsdf_value_em, bsdf_pdf_em = bsdf.eval_pdf(bsdf_ctx, si, wo, active_em)
                bsdf_value_em = si.to_world_mueller(bsdf_value_em, -wo, si.wi)
                mis_em = dr.select(ds.delta, 1, mis_weight(ds.pdf, bsdf_pdf_em))
                Lr_dir = β * mi.Spectrum(mis_em) * bsdf_value_em * em_weight

                st = self._add(col, voxel0, st, distance + ds.dist * η, Lr_dir * ray_weight,
                               active & pixel_ok)

                # ------------------ Detached BSDF sampling -------------------
                bsdf_sample, bsdf_weight = bsdf.sample(bsdf_ctx, si, sampler.next_1d(),
                                                       sampler.next_2d(), active_next)
                bsdf_weight = si.to_world_mueller(bsdf_weight, -bsdf_sample.wo, si.wi)
                L = L + Le + Lr_dir
                ray = si.spawn_ray(si.to_world(bsdf_sample.wo))
                η *= bsdf_sample.eta
                β = β * bsdf_weight
                prev_si = dr.detach(si, True)
                prev_bsdf_pdf = bsdf_sample.pdf
                prev_bsdf_delta = mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Delta)

                # -------------------- Stopping criterion ---------------------
                β_max = dr.max(mi.unpolarized_spectrum(β))
                active_next &= (β_max != 0)
                rr_prob = dr.minimum(β_max * η**2, .95)
                active_next &= rr_prob > 0
                rr_active = depth >= self.rr_depth
                β[rr_active] *= dr.rcp(rr_prob) & (rr_prob > 0)
                rr_continue = sampler.next_1d() < rr_prob
                active_next &= ~rr_active | rr_continue

                depth[si.is_valid()] += 1
                active = active_next

            self._finish(col, voxel0, st)
            return L, (depth != 0), [], L

    mi.register_integrator(PLUGIN, lambda props: TransientPathStats(props))
    _REGISTERED["cls"] = TransientPathStats
    return TransientPathStats


class StatsCollector:
    """Float64 per-bin statistics filled by :class:`TransientPathStats` (collector (b)).

    Subclasses drive another slot integrator by overriding :attr:`plugin` and
    :meth:`define_integrator` (``transient_prbvolpath``:
    :class:`~dbench.datasets.transient.collector_media.MediaStatsCollector`).

    Args:
        scene: a loaded Mitsuba scene with a ``transient_hdr_film`` (its window and size are read
            from the film).
        transform, lam: the sample transform (docs/methods/statistical.md §3; transient default identity).
        max_depth, rr_depth, camera_unwarp: integrator settings (same meaning as
            ``transient_path`` / ``transient_prbvolpath``).
        slots: per-path slots (0 = 2·max_depth, exact).

    ``render(spp, seed)`` may be called repeatedly (e.g. spp passes of 1 spp with the seeds of
    collector (a)); the sums and the sample count accumulate. ``result()`` returns the mean
    colour, the :class:`~dbench.data.SampleStats` and the ``non_zero`` counts.
    """

    #: the slot integrator's plugin name
    plugin = PLUGIN

    @staticmethod
    def define_integrator():
        """Define and register the slot integrator (once per process)."""
        return _define()

    def __init__(self, scene, transform: str = "identity", lam: float = 0.5, max_depth: int = 8,
                 rr_depth: int = 5, camera_unwarp: bool = False, slots: int = 0):
        check_transform(transform, lam)
        mi = mitsuba()
        import drjit as dr

        self.define_integrator()
        self.mi, self.dr = mi, dr
        self.scene = scene
        film = scene.sensors()[0].film()
        if not hasattr(film, "temporal_bins"):
            raise ValueError("StatsCollector: the scene's film is not a transient_hdr_film")
        self.start_opl = float(film.start_opl)
        self.bin_width_opl = float(film.bin_width_opl)
        self.bins = int(film.temporal_bins)
        size = film.crop_size()
        self.width, self.height = int(size[0]), int(size[1])
        self.transform, self.lam = transform, float(lam)
        self.k = transform_of_zero(transform, lam)
        self.code = TRANSFORMS.index(transform)
        self.integrator = mi.load_dict({"type": self.plugin, "max_depth": int(max_depth),
                                        "rr_depth": int(rr_depth),
                                        "camera_unwarp": bool(camera_unwarp),
                                        "slots": int(slots)})
        self.integrator.collector = self
        self.slots = self.integrator.slots
        self.keep_plain = transform != "identity"
        #: Dr.Jit reduction strategy of the plain sums, totals and counters (the power sums:
        #: VoxelSums)
        self.mode = dr.ReduceMode.Auto
        self.reset()

    # -- state -----------------------------------------------------------------------------------

    @property
    def size(self) -> int:
        return self.height * self.width * self.bins * 3

    def reset(self) -> None:
        dr, mi = self.dr, self.mi
        n = self.size
        self.state = VoxelSums(n)  # S1, S2, S3 and the non_zero counts
        self.plain = dr.zeros(mi.Float64, n) if self.keep_plain else None
        # per pixel and channel: Σ total, Σ total² of the paths' window totals (identity)
        self.totals = dr.zeros(mi.Float64, 2 * self.height * self.width * 3)
        # n_nonfinite, n_clamped, n_overflow, n_reentry
        self.counters = dr.zeros(mi.UInt32, 4)
        self.n = 0
        self.render_s = 0.0
        self.steady = None

    def release(self) -> None:
        """Drop the statistics state (``reset`` allocates it again)."""
        self.state = self.plain = self.totals = None
        self.counters = None

    def nbytes(self) -> int:
        """Bytes of the statistics state (independent of spp by construction)."""
        arrays = [*self.state.arrays(), self.counters, self.totals]
        if self.plain is not None:
            arrays.append(self.plain)
        return int(sum(dr_nbytes(a) for a in arrays))

    # -- device side (called while tracing the integrator) ---------------------------------------

    def _transform(self, x):
        """u = g(x) − g(0) in float64, with the host collector's exact operations."""
        dr = self.dr
        if self.code == 0:
            return x
        if self.code == 1:
            if self.lam == 0.5:
                y = (dr.sqrt(x) - 1.0) / self.lam
            else:
                y = (dr.power(x, self.lam) - 1.0) / self.lam
            return y - self.k
        lam = self.lam
        pos = x >= 0.0
        if lam == 0.0:
            yp = dr.log(x + 1.0)
        else:
            yp = (dr.power(dr.maximum(x, 0.0) + 1.0, lam) - 1.0) / lam
        if lam == 2.0:
            yn = -dr.log(1.0 - dr.minimum(x, 0.0))
        else:
            yn = -(dr.power(1.0 - dr.minimum(x, 0.0), 2.0 - lam) - 1.0) / (2.0 - lam)
        return dr.select(pos, yp, yn) - self.k

    def _scatter(self, voxel, value, active, total=None):
        """Flush one slot per lane: ``value`` (Spectrum, the path's float32 sum in the bin) into
        voxel ``voxel`` = (y·W + x)·T + bin. Returns the lane's (non-finite, clamped) counts.
        ``total`` (3 Float64, the path's running window total) gets the flushed finite values.

        Per channel: S1 += u, S2 += u², S3 += u³ (u = g(x) − g(0), float64), non_zero += [x ≠ 0]
        (:meth:`VoxelSums.add`), and the plain sum when kept."""
        dr, mi = self.dr, self.mi
        n_bad = mi.UInt32(0)
        n_neg = mi.UInt32(0)
        us, nonzero = [], []
        base = voxel * 3
        for c in range(3):
            x = mi.Float64(value[c])
            finite = dr.isfinite(x)
            n_bad += dr.select(active & ~finite, 1, 0)
            x = dr.select(finite, x, 0.0)
            if total is not None:
                total[c] = total[c] + dr.select(active, x, 0.0)
            if self.code == 1:
                n_neg += dr.select(active & (x < 0.0), 1, 0)
                x = dr.maximum(x, 0.0)
            us.append(self._transform(x))
            nonzero.append(x != 0.0)
            if self.plain is not None:
                dr.scatter_reduce(dr.ReduceOp.Add, self.plain, x, base + c, active,
                                  mode=self.mode)
        self.state.add(voxel, us, nonzero, active)
        return n_bad, n_neg

    def _add_total(self, voxel0, total) -> None:
        """Add a path's window total and its square (per channel, float64) to its pixel's
        sums; ``voxel0`` = (y·W + x)·T. Zero totals add nothing, so they need no atomics."""
        dr, mi = self.dr, self.mi
        pixel = voxel0 // mi.UInt32(self.bins)
        inside = pixel < mi.UInt32(self.height * self.width)
        for c in range(3):
            j = (pixel * 3 + c) * 2
            active = inside & (total[c] != 0.0)
            dr.scatter_reduce(dr.ReduceOp.Add, self.totals, total[c], j, active, mode=self.mode)
            dr.scatter_reduce(dr.ReduceOp.Add, self.totals, total[c] * total[c], j + 1, active,
                              mode=self.mode)

    def total_var(self) -> np.ndarray | None:
        """(H, W, 3) float64 variance of the mean of the paths' window totals, None below 2
        samples (:func:`~dbench.datasets.stats.variance_of_mean`)."""
        t = _host(self.totals).reshape(self.height, self.width, 3, 2)
        return variance_of_mean(self.n, t[..., 0], t[..., 1])

    def _count(self, n_bad, n_neg) -> None:
        """Add per-lane diagnostic counts (once per path) to the counters."""
        dr, mi = self.dr, self.mi
        dr.scatter_reduce(dr.ReduceOp.Add, self.counters, n_bad, mi.UInt32(0), n_bad > 0)
        if self.code == 1:
            dr.scatter_reduce(dr.ReduceOp.Add, self.counters, n_neg, mi.UInt32(1), n_neg > 0)

    # -- host side ------------------------------------------------------------------------------

    def render(self, spp: int, seed: int) -> np.ndarray:
        """Render ``spp`` samples per pixel in one call; returns the steady image (H, W, 3)."""
        mi, dr = self.mi, self.dr
        cap = self.state.max_samples
        if cap is not None and self.n + int(spp) > cap:
            raise ValueError(f"StatsCollector: at most {cap} samples per pixel "
                             "(packed non_zero counters)")
        t0 = time.perf_counter()
        steady, _ = mi.render(self.scene, integrator=self.integrator, spp=int(spp),
                              seed=int(seed))
        arrays = [*self.state.arrays(), self.counters, self.totals]
        if self.plain is not None:
            arrays.append(self.plain)
        dr.eval(steady, *arrays)
        dr.sync_thread()  # kernels run asynchronously: wait for the scatters too
        self.render_s += time.perf_counter() - t0
        self.n += int(spp)
        steady = np.array(steady, dtype=np.float64)
        self.steady = steady * spp if self.steady is None else self.steady + steady * spp
        return steady

    def power_sums(self, unpack: bool = True) -> dict[str, np.ndarray]:
        """Host arrays: s1, s2, s3, plain (float64) and non_zero (int32; left out when
        ``unpack`` is False), each (H, W, T, 3)
        (s1, s2, s3 are columns of ``interleaved``, (H·W·T·3, 3 or 4)); with the identity transform
        ``plain`` is ``s1`` itself. On the LLVM backend these are zero-copy views of the device
        arrays (they keep them alive; :meth:`reset` allocates new ones)."""
        shape = (self.height, self.width, self.bins, 3)
        flat, counts = self.state.host(counts=unpack)
        sums = flat.reshape(shape + (flat.shape[1],))
        s1 = sums[..., 0]
        out = {"s1": s1, "interleaved": flat,
               "s2": sums[..., 1],
               "s3": sums[..., 2]}
        if unpack:
            out["non_zero"] = counts.reshape(shape)
        out["plain"] = (_host(self.plain).reshape(shape)
                        if self.plain is not None else s1)
        return out

    def moments(self, rtol: float, rows: bool = True,
                stats: bool = True) -> dict[str, np.ndarray]:
        """Mean, variance of the mean and third central moment (float64), the mean colour
        (float32), each (H, W, T, 3), and the unpacked ``non_zero`` counts (int32), computed on
        the device from the power sums; with ``rows``, ``rows`` and ``color_rows`` ((H, W, T)
        bool) too: the rows of the statistics and of the colour the cache stores, and
        ``kept_stats``, ``kept_color``: {name: (kept rows, 3)} those rows of each array, gathered
        on the device (:mod:`.stored_rows`).
        ``stats=False`` gives the colour (and ``color_rows``) alone, for a caller that asked for
        no statistics: 6 ms instead of 10 at 128² × 100 bins (2-core CPU, LLVM).

        The arithmetic is that of :func:`dbench.datasets.stats.stats_from_sums` operation
        for operation (docs/methods/statistical.md §4.1), so the results are bit-identical to it (tested):
        the divisors are opaque so Dr.Jit does not turn a division by a constant into a
        multiplication by its reciprocal, and it contracts nothing into FMAs. Done here rather
        than on the host because the host pass wrote 80 MB of freshly allocated arrays per
        64²×200 video, and their page faults cost more than the moments (about 35 ms against
        5 ms here, out of Dr.Jit's reused memory pool). ``rtol``: the zero-variance tolerance.
        """
        mi, dr = self.mi, self.dr
        if self.n < 1:
            raise RuntimeError("StatsCollector.moments: nothing rendered yet")
        F = mi.Float64
        n = float(self.n)
        count = dr.opaque(F, n)
        shape = (self.height, self.width, self.bins, 3)
        s1, s2, s3, non_zero = self.state.gather(dr.arange(mi.UInt32, self.size))
        if not stats:  # (s2, s3 and the counts are then never evaluated)
            color = mi.Float32((self.plain if self.plain is not None else s1) / count)
            flag = stored_rows.colour_flags(color) if rows else None
            dr.eval(color, flag)
            if not rows:
                return {"color": _host(color).reshape(shape)}
            (col,) = stored_rows.row_masks(flag)
            return {"color": _host(color).reshape(shape), "color_rows": _host(col).reshape(
                shape[:-1]), "kept_color": stored_rows.kept(col, color=color)}
        safe_n = dr.opaque(F, max(n, 1.0))
        denom = dr.opaque(F, max(n - 1.0, 1.0))
        a = s1 / safe_n
        s2n = s2 / safe_n
        m2b = s2n - a * a
        zero = (m2b <= dr.opaque(F, float(rtol)) * s2n) | (n < 2.0)
        m2b = dr.select(zero, 0.0, m2b)
        m3 = dr.select(zero, 0.0, s3 / safe_n - 3.0 * a * m2b - a * a * a)
        sigma2 = m2b * count / denom if n >= 2.0 else dr.zeros(F, self.size)
        var_mean = sigma2 / safe_n
        mean = a + dr.opaque(F, float(self.k))
        color = mi.Float32((self.plain if self.plain is not None else s1) / count)
        flags = stored_rows.value_flags(mean, var_mean, m3, non_zero, color) if rows else ()
        dr.eval(mean, var_mean, m3, color, non_zero, *flags)
        found = stored_rows.row_masks(*flags)
        out = {name: _host(value).reshape(shape) for name, value in
               (("mean", mean), ("var_mean", var_mean), ("m3", m3), ("color", color),
                ("non_zero", non_zero))}
        out.update({name: _host(value).reshape(shape[:-1]) for name, value in
                    zip(("rows", "color_rows"), found)})
        if rows:  # (one gather of them all where the colour keeps the statistics' rows)
            same = np.array_equal(out["rows"], out["color_rows"])
            out["kept_stats"] = stored_rows.kept(found[0], mean=mean, var_mean=var_mean, m3=m3,
                                                 non_zero=non_zero, **({"color": color} if same
                                                                       else {}))
            out["kept_color"] = {"color": out["kept_stats"].pop("color")} if same else \
                stored_rows.kept(found[1], color=color)
        return out

    def diagnostics(self) -> dict[str, int]:
        c = np.array(self.counters, dtype=np.int64)
        return {"n_nonfinite": int(c[0]), "n_clamped": int(c[1]), "n_overflow": int(c[2]),
                "n_reentry": int(c[3])}

    def result(self, sums: dict | None = None):
        """(color (H, W, T, 3) float32, SampleStats, non_zero (H, W, T, 3) int32).

        ``sums``: the output of :meth:`power_sums` when the caller already has it."""
        if self.n < 1:
            raise RuntimeError("StatsCollector.result: nothing rendered yet")
        p = self.power_sums() if sums is None else sums
        stats = stats_from_power_sums(self.n, p["s1"], p["s2"], p["s3"], self.k, self.transform,
                                      self.lam, diagnostics=self.diagnostics())
        color = (p["plain"] / self.n).astype(np.float32)
        return color, stats, p["non_zero"]
