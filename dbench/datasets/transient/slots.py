"""Per-path slots of the in-integrator collectors (docs/methods/statistical.md §11.2, mode B).

:class:`SlotIntegrator` is a mixin for mitransient integrators: ``transient_path``
(:mod:`dbench.datasets.transient.collector`) and ``transient_prbvolpath``
(:mod:`dbench.datasets.transient.collector_media`). It replaces the film histogram callback by
per-path *slots*, (bin, float32 running sum) pairs carried as registers of the symbolic loop in a
:class:`PathSlots`, and flushes them into the float64 power sums of a
:class:`~dbench.datasets.transient.collector.StatsCollector` (``col._scatter``).

An integrator's ``sample()`` calls, per path (one lane):

* :meth:`SlotIntegrator._open` before its loop: the pixel's first voxel, the ray weight and an
  empty :class:`PathSlots`;
* :meth:`SlotIntegrator._add` wherever the plain integrator calls ``add_transient(contrib, opl,
  …)``: the bin is ``floor((opl − start)/width)``, computed as the film computes it; outside
  [0, T), zero or off the film the contribution is ignored (the film ignores it too, or adds 0).
  A bin already in a slot adds to that slot's running sum (in path order, exactly as the film
  histogram adds it in a 1-spp pass); a new bin takes the first free slot;
* :meth:`SlotIntegrator._release` once per vertex when fewer slots than a path can fill were
  asked for: the slots of bins the path's OPL has passed are final (every later contribution
  lies at or after the current OPL) and are flushed and freed;
* :meth:`SlotIntegrator._finish` after the loop: every open slot is flushed, and the per-path
  diagnostic counts go to the collector's counters.

Overflow (a contribution that finds every slot busy) is counted in ``n_overflow``; the
statistics are exact whenever ``n_overflow == 0`` (a positive count means some path may have
given a bin two samples; it need not have). With ``slots < 2·max_depth`` the oldest
slot is flushed early and reused (``slots = 1`` is the seed's Alg. 4 as printed: flush on every
bin change). With ``slots ≥ 2·max_depth`` no slot ages are kept: an integrator whose paths can
never exceed 2·max_depth contributions (``guard_overflow = False``) does not check at all; one
that can only in unusual scenes (``guard_overflow = True``) flushes the contribution on its own
(one extra sample in that bin) and counts it.

Each slot's flush and, with every slot kept (no ages), a contribution's insertion run inside
symbolic ``dr.if_stmt`` branches on their lanes' masks, which Dr.Jit compiles to real branches:
a packet of lanes none of which contributes (most emitter hits) or uses the slot (the last ones)
skips that work instead of computing it masked. The sums are bit for bit those of the masked
form (README.md, "How renders work", gives the timings).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi


@dataclass
class PathSlots:
    """The slot state of one path per lane (k = the integrator's ``slots``).

    Attributes:
        bins: k × Int32, the slot's bin (−1 = free).
        vals: k × Spectrum, the path's float32 running sum in that bin.
        ages: k × UInt32, the clock when the slot was opened; empty when no slot is ever forced
            out (k ≥ 2·max_depth).
        last: Int32, the previous contribution's bin (re-entry diagnostics).
        clock: UInt32, contributions offered so far.
        n_re: UInt32, contributions to an open bin other than the previous one (re-entries).
        n_over: UInt32, contributions that found every slot busy.
        bad, neg: UInt32, flushed channel values that were non-finite / negative (clamped).
        total: 3 × Float64, the path's flushed values summed over bins (its time-integrated
            contribution inside the window, for ``TransientFrame.total_var``).
    """

    bins: list
    vals: list
    ages: list
    last: object
    clock: object
    n_re: object
    n_over: object
    bad: object
    neg: object
    total: list


def with_slots(base: type) -> type:
    """``base`` (a mitransient integrator class) extended by the methods of
    :class:`SlotIntegrator`. Integrators are nanobind types, which allow a single base class
    only, so the mixin's methods are copied into one intermediate subclass."""
    members = {k: v for k, v in vars(SlotIntegrator).items()
               if not (k.startswith("__") and k.endswith("__"))}
    return type(f"{base.__name__}Slots", (base,), members)


class SlotIntegrator:
    """Mixin: per-path slots instead of the film histogram (see the module docstring).

    Used through :func:`with_slots` (``class X(with_slots(TransientPath))``); the integrator
    calls :meth:`_init_slots` in its ``__init__`` and the methods above in ``sample()``; a
    :class:`StatsCollector` must be attached (``integrator.collector = col``) before
    rendering."""

    #: paths of this integrator may, in unusual scenes, add more than 2·max_depth contributions
    guard_overflow = False

    def _init_slots(self, props, plugin: str) -> None:
        slots = int(props.get("slots", 0))
        if self.max_depth < 1:
            raise ValueError(f"{plugin} needs a finite max_depth >= 1")
        self.slots = slots if slots > 0 else 2 * self.max_depth
        self.collector = None
        self._pos = None
        self._weight = None

    @property
    def exact(self) -> bool:
        """Enough slots for every contribution of a path (2 per vertex): no ages kept."""
        return self.slots >= 2 * self.max_depth

    # the base render() builds this callback right before calling sample(): keep what the
    # collector needs (pixel positions, ray weights); the film histogram is not written
    def add_transient_f(self, film, pos, ray_weight, sample_scale):
        self._pos = pos
        self._weight = ray_weight
        return lambda *args, **kwargs: None

    def _open(self, plugin: str):
        """(collector, first voxel (y·W + x)·T of the lane's pixel (UInt32), pixel inside the
        film (Bool), ray weight (Spectrum), empty :class:`PathSlots`)."""
        col = self.collector
        if col is None:
            raise RuntimeError(f"{plugin}: attach a StatsCollector first")
        pos = self._pos
        px = mi.UInt32(dr.floor(pos.x))
        py = mi.UInt32(dr.floor(pos.y))
        pixel_ok = (pos.x >= 0) & (pos.y >= 0) & (px < col.width) & (py < col.height)
        voxel0 = (py * col.width + px) * col.bins
        k = self.slots
        st = PathSlots(bins=[mi.Int32(-1) for _ in range(k)],
                       vals=[mi.Spectrum(0.0) for _ in range(k)],
                       ages=[] if self.exact else [mi.UInt32(0) for _ in range(k)],
                       last=mi.Int32(-1), clock=mi.UInt32(0), n_re=mi.UInt32(0),
                       n_over=mi.UInt32(0), bad=mi.UInt32(0), neg=mi.UInt32(0),
                       total=[mi.Float64(0.0) for _ in range(3)])
        return col, voxel0, pixel_ok, mi.Spectrum(self._weight), st

    def _insert(self, st: PathSlots, b, v, ok):
        """Add contribution ``v`` (mask ``ok``) of bin ``b`` into the slots. Returns (no slot
        found or free, re-entry)."""
        found = mi.Bool(False)
        for i in range(self.slots):
            m = ok & (st.bins[i] == b)
            st.vals[i] = dr.select(m, st.vals[i] + v, st.vals[i])
            found |= m
        # a re-entry: the bin is open but was not the previous contribution's bin
        reentry = found & (b != st.last)
        need = ok & ~found
        # the first free slot takes a new bin
        for i in range(self.slots):
            e = need & (st.bins[i] < 0)
            st.bins[i] = dr.select(e, b, st.bins[i])
            st.vals[i] = dr.select(e, v, st.vals[i])
            if st.ages:
                st.ages[i] = dr.select(e, st.clock, st.ages[i])
            need &= ~e
        return need, reentry

    def _add(self, col, voxel0, st: PathSlots, opl, v, mask) -> PathSlots:
        """One contribution ``v`` (Spectrum, contribution × ray weight) at optical path length
        ``opl`` (Float), where ``mask`` (Bool: the integrator's own mask and the pixel's)."""
        t = (opl - col.start_opl) / col.bin_width_opl
        ok = mask & (t >= 0) & (t < col.bins) & dr.any(v != 0.0)
        b = mi.Int32(dr.floor(t))
        if st.ages:
            over, re = self._insert(st, b, v, ok)
            st.n_re += dr.select(re, 1, 0)
            st.last = dr.select(ok, b, st.last)
            st.clock += 1
            self._overflow(col, voxel0, st, over, b, v)
            return st

        def add(ok, b, v, bins, vals, last, n_re, n_over, bad, neg, *total):
            # on copies: the branch's results are what it returns
            s = PathSlots(bins=list(bins), vals=list(vals), ages=[], last=last, clock=None,
                          n_re=n_re, n_over=n_over, bad=bad, neg=neg, total=list(total))
            over, re = self._insert(s, b, v, ok)
            n_re = n_re + dr.select(re, 1, 0)
            last = dr.select(ok, b, last)
            if self.guard_overflow:
                # more contributions than 2·max_depth: flushed alone (inexact, counted)
                n_over = n_over + dr.select(over, 1, 0)
                nb, nn = col._scatter(voxel0 + mi.UInt32(dr.maximum(b, 0)), v, over, s.total)
                bad, neg = bad + nb, neg + nn
            return s.bins, s.vals, last, n_re, n_over, bad, neg, *s.total

        def skip(ok, b, v, bins, vals, last, n_re, n_over, bad, neg, *total):
            return bins, vals, last, n_re, n_over, bad, neg, *total

        # a real branch: a packet of lanes none of which contributes here (most emitter hits
        # and light samples of a path miss the window or carry nothing) skips the slots
        st.bins, st.vals, st.last, st.n_re, st.n_over, st.bad, st.neg, *st.total = dr.if_stmt(
            (ok, b, v, st.bins, st.vals, st.last, st.n_re, st.n_over, st.bad, st.neg, *st.total),
            ok, add, skip, mode="symbolic")
        st.clock += 1
        return st

    def _overflow(self, col, voxel0, st: PathSlots, over, b, v) -> None:
        """Every slot busy (only with slots < 2·max_depth): flush the oldest slot early (counted
        in ``n_overflow``; the statistics are then inexact) and give it to the new bin."""
        st.n_over += dr.select(over, 1, 0)
        oldest = mi.UInt32(0xFFFFFFFF)
        for i in range(self.slots):
            oldest = dr.minimum(oldest, st.ages[i])
        taken = mi.Bool(False)
        for i in range(self.slots):
            e = over & ~taken & (st.ages[i] == oldest)
            nb, nn = col._scatter(voxel0 + mi.UInt32(dr.maximum(st.bins[i], 0)), st.vals[i], e,
                                  st.total)
            st.bad += nb
            st.neg += nn
            st.bins[i] = dr.select(e, b, st.bins[i])
            st.vals[i] = dr.select(e, v, st.vals[i])
            st.ages[i] = dr.select(e, st.clock, st.ages[i])
            taken |= e

    def _flush(self, col, voxel0, st: PathSlots, limit=None) -> None:
        """Scatter every slot whose bin is < ``limit`` (Int32; all when None) and free it."""
        for i in range(self.slots):
            act = st.bins[i] >= 0
            if limit is not None:
                act &= st.bins[i] < limit

            def flush(act, voxel, value, t0, t1, t2):
                total = [t0, t1, t2]
                nb, nn = col._scatter(voxel, value, act, total)
                return nb, nn, *total

            def keep(act, voxel, value, t0, t1, t2):
                return mi.UInt32(0), mi.UInt32(0), t0, t1, t2

            nb, nn, *st.total = dr.if_stmt(
                (act, voxel0 + mi.UInt32(dr.maximum(st.bins[i], 0)), st.vals[i], *st.total),
                act, flush, keep, mode="symbolic")
            st.bad += nb
            st.neg += nn
            st.bins[i] = dr.select(act, -1, st.bins[i])
            st.vals[i] = dr.select(act, mi.Spectrum(0.0), st.vals[i])

    def _release(self, col, voxel0, st: PathSlots, opl, mask) -> PathSlots:
        """With fewer slots than contributions (ages kept), flush the slots of bins before the
        path's current OPL (Float) where ``mask``; a no-op otherwise (everything is flushed at
        the path's end, which measured faster than flushing inside the loop)."""
        if st.ages:
            base = (opl - col.start_opl) / col.bin_width_opl
            base_bin = mi.Int32(dr.floor(dr.clip(base, -1.0, col.bins)))
            self._flush(col, voxel0, st, limit=dr.select(mask, base_bin, -1))
        return st

    def _finish(self, col, voxel0, st: PathSlots) -> None:
        """Flush every open slot and add the per-path counts (once per path) to the counters."""
        self._flush(col, voxel0, st)
        col._add_total(voxel0, st.total)
        col._count(st.bad, st.neg)
        dr.scatter_reduce(dr.ReduceOp.Add, col.counters, st.n_re, mi.UInt32(3), st.n_re > 0)
        if st.ages or self.guard_overflow:
            dr.scatter_reduce(dr.ReduceOp.Add, col.counters, st.n_over, mi.UInt32(2),
                              st.n_over > 0)
