"""The GPU kernels compiled for a CUDA target on a machine without a GPU
(dbench/methods/kernels/gpu/aot.py, dbench/speed/kernels.py; docs/gpu.md §6): the launches the
device paths make are recorded on CPU tensors with the GPU's launch choices, turned into the
compilations Triton's JIT performs, and compiled for sm_90. The default run compiles a cheap
kernel and checks the specialisations; the slow run compiles every variant."""
import pytest
import torch

from dbench.methods.kernels.gpu import aot, runtime
from dbench.methods.kernels.gpu.temporal import GPU_BLOCK, accumulate_kernel, block_for
from dbench.speed import kernels

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the interpreter's NaN lanes


@pytest.fixture(scope="module")
def recorded():
    return kernels.record_launches()


def test_gpu_layout_gives_cpu_tensors_the_gpu_launch_choices():
    assert block_for(4096, torch.device("cpu")) == 4096  # the interpreter's whole image
    with runtime.gpu_layout():
        assert block_for(4096, torch.device("cpu")) == GPU_BLOCK
    assert block_for(4096, "cpu") == 4096
    assert block_for(10, torch.device("cuda", 0)) == GPU_BLOCK


def test_a_dry_recording_launches_nothing_and_a_plain_one_runs():
    n = 16
    args = lambda out: (torch.ones((n, 3)), torch.zeros(1), torch.zeros(1), torch.zeros(1),
                        out, torch.zeros(1), 0.1, 4, 4, 1)  # noqa: E731
    out = torch.full((n, 3), 7.0)
    with runtime.recording(execute=False) as seen:
        accumulate_kernel[(1,)](*args(out), BLOCK=16)
    assert len(seen) == 1 and seen[0].kernel is accumulate_kernel and seen[0].meta == {
        "BLOCK": 16}
    assert torch.all(out == 7.0)  # not run


def test_every_device_path_is_recorded(recorded):
    assert set(recorded) == {"statistical", "jbf", "accumulate", "svgf", "asvgf", "bmfr",
                             "statistical (transient)"}  # nca, autoencoder, oidn: no Triton
    names = {launch.kernel.__name__ for ls in recorded.values() for launch in ls}
    assert {"window_kernel", "window3d_kernel", "reproject_kernel", "accumulate_kernel",
            "temporal_kernel", "variance_kernel", "atrous_kernel", "strata_kernel",
            "bmfr_accumulate_kernel", "bmfr_fit_kernel", "handback_low_kernel",
            "handback_energy_kernel", "bmfr_finish_kernel"} <= names


def test_values_that_change_per_frame_or_per_pass_compile_no_variants(recorded):
    """À-trous steps 1, 2, 4, 8, 16, bmfr's per-frame block offsets and noise seeds, and the
    length of the window's γ table would each make Triton compile another variant (an integer
    equal to 1 becomes a constant, a multiple of 16 gets a hint) in the middle of a timed run;
    the kernels exclude them from specialisation."""
    atrous = [x for x in recorded["asvgf"] if x.kernel.__name__ == "atrous_kernel"]
    at = [p.name for p in atrous[0].kernel.jit().params].index("step")
    assert {x.args[at] for x in atrous} >= {1, 2, 4}
    assert len(aot.variants(atrous)) == len({tuple(sorted(x.meta.items())) for x in atrous})
    fits = [x for x in recorded["bmfr"] if x.kernel.__name__ == "bmfr_fit_kernel"]
    assert len(fits) == kernels.FRAMES and len(aot.variants(fits)) == 1


def test_an_integer_argument_is_specialised_as_the_jit_does():
    # accumulate_kernel(color, fetched, status, new, out, var, alpha_min, n_max, H, W, BLOCK)
    launch = runtime.Launch(accumulate_kernel, (torch.ones((16, 3)),) + (torch.zeros(4),) * 5
                            + (0.1, 256.0, 1, 32), {"BLOCK": 128})
    v = aot.variant_of(launch)
    sig = dict(v.signature)
    assert sig["H"] == "constexpr" and sig["W"] == "i32" and sig["alpha_min"] == "fp32"
    names = [p.name for p in accumulate_kernel.jit().params]
    attrs = dict(v.attrs)
    assert (names.index("W"),) in attrs and (names.index("color_ptr"),) in attrs  # ÷16, aligned
    assert dict(v.constexprs)[(names.index("H"),)] == 1


def test_the_compiled_source_hashes_as_the_jits(recorded):
    """Triton's cache key of a variant compiled here is the JIT's for the same launch, so the
    precompiled kernels are found by ``dbench bench gpu``'s timed warm-up."""
    from triton.compiler import ASTSource
    from triton.runtime.jit import create_function_from_signature

    launch = next(x for x in recorded["bmfr"] if x.kernel.__name__ == "bmfr_finish_kernel")
    jf = launch.kernel.jit()
    backend = aot._backend(aot.DEFAULT_ARCH)
    kwargs = dict(launch.meta, debug=False, instrumentation_mode="")
    bound, spec, opts = create_function_from_signature(jf.signature, jf.params,
                                                       backend)(*launch.args, **kwargs)
    _, signature, constexprs, attrs = jf._pack_args(backend, kwargs, bound, spec, opts)
    assert attrs, "the launch should carry divisibility hints"
    jit_src = ASTSource(jf, signature, constexprs, attrs)  # as JITFunction._do_compile builds it
    assert aot.source_of(aot.variant_of(launch)).hash() == jit_src.hash()


@pytest.mark.parametrize("label, name", [("accumulate", "accumulate_kernel"),
                                         ("statistical", "window_kernel"),
                                         ("statistical (transient)", "window3d_kernel")])
def test_a_kernel_compiles_for_sm90(recorded, label, name):
    """The cheap variants in the default run (seconds each); every one in the slow run."""
    v = next(x for x in aot.variants(recorded[label]) if x.name == name)
    row = aot.compile_variant(v)
    assert "error" not in row and row["cubin_bytes"] > 1000 and name in row["variant"]


@pytest.mark.slow
def test_every_kernel_variant_compiles_for_sm90():
    result = kernels.precompile(arch=90, jobs=2)
    assert result["variants"] >= 20
    failed = [(r["variant"], r["error"]) for r in result["rows"] if "error" in r]
    assert not failed, failed


def test_variants_follow_the_frame_size_so_bench_gpu_records_at_its_own(monkeypatch):
    """A-SVGF's strata are ⌈H/3⌉ × ⌈W/3⌉: at 48 rows they are 16 (a multiple of 16, a variant of
    its own), at 16 rows 6. ``precompile`` records at every size it is given and compiles the
    union (here with the compiler replaced by a stand-in)."""
    small = kernels.record_launches(["asvgf"], transient=False, size=(16, 32))
    tall = kernels.record_launches(["asvgf"], transient=False, size=(48, 32))
    names = {v.name for v in set(aot.variants(tall["asvgf"])) - set(aot.variants(small["asvgf"]))}
    assert "strata_kernel" in names
    seen = []
    monkeypatch.setattr(aot, "compile_all", lambda found, arch, jobs: seen.extend(found) or [
        {"kernel": v.name, "variant": v.label, "seconds": 0.0} for v in found])
    result = kernels.precompile(arch=90, jobs=1, methods=["asvgf"], sizes=[(16, 32), (48, 32)])
    assert set(seen) == set(aot.variants(small["asvgf"])) | set(aot.variants(tall["asvgf"]))
    assert result["variants"] == len(seen) and all(r["methods"] == ["asvgf"]
                                                   for r in result["rows"])
