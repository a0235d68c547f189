"""Collector (b) for participating media: per-bin statistics inside ``transient_prbvolpath``.

docs/methods/statistical.md §11.1-11.2 (mode B), docs/transient.md §5. :class:`TransientPRBVolpathStats`
(plugin ``transient_prbvolpath_stats``) re-implements the primal path of mitransient 1.3.1's
``transient_prbvolpath`` (delta tracking, next-event estimation at surface and medium scatter
vertices, Russian roulette) operation for operation and with the same random numbers, but where
that integrator adds a contribution to the film histogram it offers it to the per-path slots of
:mod:`dbench.datasets.transient.slots`; the slots are flushed into the float64 power
sums and ``non_zero`` counts of a :class:`MediaStatsCollector` (the same state and host
side as :class:`~dbench.datasets.transient.collector.StatsCollector`).

Slots: a contribution is an emitter hit (at a surface interaction, at the path's OPL) or a
next-event estimate (at a real scatter vertex, surface or medium, at OPL + η·distance to the
light sample). A path counts ``depth`` real vertices; an emitter hit happens at depth
0 … max_depth (at most one per depth: hitting an emitter with a non-null BSDF is a real vertex)
and a next-event estimate at vertices 1 … max_depth − 1, so ``slots = 2·max_depth`` (the
default) holds every contribution of a path. Null interactions (medium boundaries with a
``null`` BSDF, null collisions in heterogeneous media) add neither. Only unusual scenes break
the bound (an emitter on a null-BSDF shape, a BSDF mixing null and smooth lobes); the
integrator therefore checks it (``guard_overflow``, measured at about 5 % of a plain render): a
contribution that finds every slot busy is flushed on its own and counted in ``n_overflow``, so
the statistics are exact whenever ``n_overflow == 0``. With fewer slots the oldest slot is
forced out as in ``transient_path_stats``; the path's OPL never decreases (delta tracking and
surface hits only add η·t), so slots of bins before it are final.

For the same seeds in 1-spp passes the float64 sums, ``non_zero`` counts, colour and moments are
bit-identical to collector (a) on ``transient_prbvolpath``, homogeneous and heterogeneous media,
warped and unwarped (tests/datasets/test_transient_media_collector.py).

Memory: that of :class:`StatsCollector`, (H, W, T, 3) × 3 float64 (+1 for non-identity
transforms) + (H, W, T) uint64, whatever the spp; per path 4·slots registers (bin + RGB sum).
Primal rendering only.
"""
from __future__ import annotations

from typing import Any

import drjit as dr
import mitsuba as mi

from ..mitsuba_env import mitsuba, require_llvm
from .collector import StatsCollector
from .slots import with_slots

PLUGIN = "transient_prbvolpath_stats"
_REGISTERED: dict[str, Any] = {}


def _define():
    """Define and register the integrator class (needs the variant set and mitransient)."""
    if "cls" in _REGISTERED:
        return _REGISTERED["cls"]
    require_llvm("the in-integrator transient statistics collector (media)")
    mitsuba()
    import mitransient  # noqa: F401  (registers transient_prbvolpath, the film)
    from mitransient.integrators.transient_prbvolpath import (TransientPRBVolpathIntegrator,
                                                             index_spectrum)
    from mitsuba.ad.integrators.common import mis_weight

    # @dr.syntax recompiles sample() against the module globals, not this closure
    globals()["mis_weight"] = mis_weight
    globals()["index_spectrum"] = index_spectrum

    class TransientPRBVolpathStats(with_slots(TransientPRBVolpathIntegrator)):
        """``transient_prbvolpath`` with per-path, per-bin running sums flushed into power sums.

        Properties: those of ``transient_prbvolpath`` plus ``slots`` (int, 0 = 2·max_depth).
        Attach a :class:`MediaStatsCollector` (``integrator.collector = c``) before rendering.
        """

        guard_overflow = True

        def __init__(self, props):
            super().__init__(props)
            self._init_slots(props, PLUGIN)

        # The loop below is mitransient's primal path with the AD branches removed (they do
        # nothing in primal mode) and add_transient replaced by self._add; the sampler calls,
        # masks and arithmetic are kept in the same order, which is what makes the result
        # bit-identical to the film histogram of a 1-spp pass.
        @dr.syntax
        def sample(self, mode, scene, sampler, ray, β, δL, state_in, active, add_transient,
                   gather_derivatives_at_distance=None, **kwargs):
            if mode != dr.ADMode.Primal or gather_derivatives_at_distance is not None:
                raise NotImplementedError(f"{PLUGIN} renders primal images only")
            self.prepare_scene(scene)
            col, voxel0, pixel_ok, ray_weight, st = self._open(PLUGIN)

            ray = mi.Ray3f(ray)
            depth = mi.UInt32(0)
            L = mi.Spectrum(0)
            η = mi.Float(1)
            active = mi.Bool(active)
            si = dr.zeros(mi.SurfaceInteraction3f)
            needs_intersection = mi.Bool(True)
            last_scatter_event = dr.zeros(mi.Interaction3f)
            last_scatter_direction_pdf = mi.Float(1.0)
            medium = dr.zeros(mi.MediumPtr)
            channel = 0
            valid_ray = mi.Bool(False)
            specular_chain = mi.Bool(True)
            distance = mi.Float(0.0)
            if self.camera_unwarp:
                distance = -self.first_surface(scene, ray, active)
            if mi.is_rgb:
                n_channels = dr.size_v(mi.Spectrum)
                channel = mi.UInt32(dr.minimum(n_channels * sampler.next_1d(active),
                                               n_channels - 1))

            while dr.hint(active, label="Transient PRB Volpath Stats"):
                active &= dr.any(mi.unpolarized_spectrum(β) != 0.0)

                # --------------------- Russian roulette ---------------------
                q = dr.minimum(dr.max(mi.unpolarized_spectrum(β)) * dr.square(η), 0.99)
                perform_rr = (depth > self.rr_depth)
                active &= (sampler.next_1d(active) < q) | ~perform_rr
                β[perform_rr] = β * dr.rcp(q)

                active_medium = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
                active_surface = active & ~active_medium

                # ---------------- Medium interaction (delta tracking) ----------------
                u = sampler.next_1d(active_medium)
                mei = medium.sample_interaction(ray, u, channel, active_medium)
                mei.t = dr.detach(mei.t)
                ray.maxt[active_medium & medium.is_homogeneous() & mei.is_valid()] = mei.t
                intersect = needs_intersection & active_medium
                si[intersect] = scene.ray_intersect(ray, intersect)
                needs_intersection &= ~active_medium
                mei.t[active_medium & (si.t < mei.t)] = dr.inf

                tr, free_flight_pdf = medium.transmittance_eval_pdf(mei, si, active_medium)
                tr_pdf = index_spectrum(free_flight_pdf, channel)
                weight = mi.Spectrum(1.0)
                weight[active_medium] *= dr.select(tr_pdf > 0.0, tr / dr.detach(tr_pdf), 0.0)

                escaped_medium = active_medium & ~mei.is_valid()
                active_medium &= mei.is_valid()

                if dr.hint(self.handle_null_scattering, mode='scalar'):
                    scatter_prob = (index_spectrum(mei.sigma_t, channel)
                                    / index_spectrum(mei.combined_extinction, channel))
                    act_null_scatter = ((sampler.next_1d(active_medium) >= scatter_prob)
                                        & active_medium)
                    act_medium_scatter = ~act_null_scatter & active_medium
                    weight[act_null_scatter] *= mei.sigma_n / dr.detach(1 - scatter_prob)
                else:
                    scatter_prob = mi.Float(1.0)
                    act_medium_scatter = active_medium

                depth[act_medium_scatter] += 1
                last_scatter_event[act_medium_scatter] = dr.detach(mei)
                distance += dr.select(act_medium_scatter, mei.t * η, 0)

                active &= depth < self.max_depth
                act_medium_scatter &= active
                if dr.hint(self.handle_null_scattering, mode='scalar'):
                    ray.o[act_null_scatter] = dr.detach(mei.p)
                    si.t[act_null_scatter] = si.t - dr.detach(mei.t)

                weight[act_medium_scatter] *= mei.sigma_s / dr.detach(scatter_prob)
                β *= dr.detach(weight)
                mei = dr.detach(mei)

                phase_ctx = mi.PhaseFunctionContext(sampler)
                phase = mei.medium.phase_function()
                phase[~act_medium_scatter] = dr.zeros(mi.PhaseFunctionPtr)

                # ------------------------ Surface interaction ------------------------
                active_surface |= escaped_medium
                intersect = active_surface & needs_intersection
                si[intersect] = scene.ray_intersect(ray, intersect)
                distance[active_surface] += si.t * η

                # with fewer slots than contributions, free the slots of bins the path's OPL
                # has passed (no-op with the full slot set)
                st = self._release(col, voxel0, st, distance, pixel_ok)

                # ---------------------- Emitter hit ----------------------
                ray_from_camera = active_surface & (depth == 0)
                count_direct = ray_from_camera | specular_chain
                emitter = si.emitter(scene)
                active_e = active_surface & (emitter != None) & ~(  # noqa: E711
                    (depth == 0) & self.hide_emitters)
                ds = mi.DirectionSample3f(scene, si, last_scatter_event)
                if dr.hint(self.use_nee, mode='scalar'):
                    emitter_pdf = scene.pdf_emitter_direction(last_scatter_event, ds, active_e)
                else:
                    emitter_pdf = 0.0
                emitted = emitter.eval(si, active_e)
                contrib = dr.select(count_direct, β * emitted,
                                    β * mis_weight(last_scatter_direction_pdf, emitter_pdf)
                                    * emitted)
                L[active_e] += contrib
                st = self._add(col, voxel0, st, distance, contrib * ray_weight,
                               active_e & pixel_ok)

                active_surface &= si.is_valid()
                ctx = mi.BSDFContext()
                bsdf = si.bsdf(ray)

                # ---------------------- Next-event estimation ----------------------
                if dr.hint(self.use_nee, mode='scalar'):
                    active_e_surface = (active_surface
                                        & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                                        & (depth + 1 < self.max_depth))
                    sample_emitters = mei.medium.use_emitter_sampling()
                    specular_chain &= ~act_medium_scatter
                    specular_chain |= act_medium_scatter & ~sample_emitters
                    active_e_medium = act_medium_scatter & sample_emitters
                    active_e = active_e_surface | active_e_medium

                    emitted, ds = self.sample_emitter(mei, si, active_e_medium, active_e_surface,
                                                      scene, sampler, medium, channel, active_e,
                                                      mode=dr.ADMode.Primal)
                    bsdf_val, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d),
                                                       active_e_surface)
                    phase_val, phase_pdf = phase.eval_pdf(phase_ctx, mei, ds.d, active_e_medium)
                    nee_weight = dr.select(active_e_surface, bsdf_val, phase_val)
                    nee_directional_pdf = dr.select(ds.delta, 0.0, dr.select(
                        active_e_surface, bsdf_pdf, phase_pdf))
                    contrib = β * nee_weight * mis_weight(ds.pdf, nee_directional_pdf) * emitted
                    L[active_e] += contrib
                    st = self._add(col, voxel0, st, distance + ds.dist * η,
                                   contrib * ray_weight, active_e & pixel_ok)

                # ---------------------- Phase function sampling ----------------------
                valid_ray |= act_medium_scatter
                wo, phase_weight, phase_pdf = phase.sample(
                    phase_ctx, mei, sampler.next_1d(act_medium_scatter),
                    sampler.next_2d(act_medium_scatter), act_medium_scatter)
                act_medium_scatter &= phase_pdf > 0.0
                β[act_medium_scatter] *= phase_weight
                ray[act_medium_scatter] = mei.spawn_ray(wo)
                needs_intersection |= act_medium_scatter
                last_scatter_direction_pdf[act_medium_scatter] = phase_pdf

                # ---------------------- BSDF sampling ----------------------
                bs, bsdf_weight = bsdf.sample(ctx, si, sampler.next_1d(active_surface),
                                              sampler.next_2d(active_surface), active_surface)
                active_surface &= bs.pdf > 0
                β[active_surface] *= bsdf_weight
                η[active_surface] *= bs.eta
                bsdf_ray = si.spawn_ray(si.to_world(bs.wo))
                ray[active_surface] = bsdf_ray

                needs_intersection |= active_surface
                non_null_bsdf = active_surface & ~mi.has_flag(bs.sampled_type,
                                                               mi.BSDFFlags.Null)
                depth[non_null_bsdf] += 1
                last_scatter_event[non_null_bsdf] = si
                last_scatter_direction_pdf[non_null_bsdf] = bs.pdf

                valid_ray |= non_null_bsdf
                specular_chain |= non_null_bsdf & mi.has_flag(bs.sampled_type,
                                                              mi.BSDFFlags.Delta)
                specular_chain &= ~(active_surface & mi.has_flag(bs.sampled_type,
                                                                 mi.BSDFFlags.Smooth))
                has_medium_trans = active_surface & si.is_medium_transition()
                medium[has_medium_trans] = si.target_medium(ray.d)
                active &= (active_surface | active_medium)

            self._finish(col, voxel0, st)
            return L, valid_ray, [], L

    mi.register_integrator(PLUGIN, lambda props: TransientPRBVolpathStats(props))
    _REGISTERED["cls"] = TransientPRBVolpathStats
    return TransientPRBVolpathStats


class MediaStatsCollector(StatsCollector):
    """:class:`~dbench.datasets.transient.collector.StatsCollector` driving
    :class:`TransientPRBVolpathStats` (participating media). Same arguments, state
    (:class:`~dbench.datasets.transient.voxel_sums.VoxelSums`), ``render``, ``moments`` and
    ``result``."""

    plugin = PLUGIN

    @staticmethod
    def define_integrator():
        return _define()
