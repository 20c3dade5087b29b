"""Device listing and selection: the real OpenCL installation, and the selection rule
(:func:`clcsg.cl.device.choose`) on synthetic device lists."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

import clcsg
from clcsg.errors import DeviceError
from clcsg.cl import device as D
from clcsg.cl.device import DeviceInfo, choose


# -- the rule on synthetic lists ----------------------------------------------------------------


def info(p, d, type="cpu", platform=None, name=None, oclgrind=False, atomics=True, fp64=True):
    if platform is None:
        platform = "Oclgrind" if oclgrind else f"Platform {p}"
    return DeviceInfo(
        platform_index=p,
        device_index=d,
        platform=platform,
        name=name or ("Oclgrind Simulator" if oclgrind else f"{type} device {p}.{d}"),
        type=type,
        compute_units=4,
        fp64=fp64,
        int64_atomics=atomics,
        is_oclgrind=oclgrind,
        max_mem_alloc=1 << 30,
        global_mem=1 << 32,
    )


GRIND_FIRST = [info(0, 0, "cpu", oclgrind=True), info(1, 0, "cpu", "Portable Computing Language", "pthread-x")]
MIXED = [
    info(0, 0, "cpu", oclgrind=True),
    info(1, 0, "cpu", "Portable Computing Language", "pthread-x"),
    info(2, 0, "gpu", "NVIDIA CUDA", "GeForce RTX"),
    info(2, 1, "gpu", "NVIDIA CUDA", "Tesla T4"),
]


def test_default_prefers_gpu_and_skips_oclgrind():
    assert choose(MIXED, None, {}) == 2
    assert choose(GRIND_FIRST, None, {}) == 1
    assert choose(GRIND_FIRST, None, None) == 1


def test_a_device_whose_compiler_fails_is_passed_over_by_rule_only():
    """The pip PoCL that cannot compile for the CPU ("unknown target CPU 'generic'"), listed
    first, is passed over by the default and ``cpu``; a name or PYOPENCL_CTX still means it."""
    broken = "error: unknown target CPU 'generic'"
    infos = [info(0, 0, "cpu", "Portable Computing Language", "pthread-AMD EPYC"),
             info(1, 0, "cpu", "Portable Computing Language", "pthread-skylake-avx512-AMD EPYC"),
             info(2, 0, "cpu", oclgrind=True)]
    fails = {0: broken}
    tried = []

    def build_error(k):
        tried.append(k)
        return fails.get(k)

    assert D.choose_usable(infos, None, {}, build_error) == 1 and tried == [0, 1]
    assert D.choose_usable(infos, "cpu", {}, build_error) == 1
    for spec, env in (("0:0", {}), (None, {"PYOPENCL_CTX": "0"})):
        with pytest.raises(DeviceError) as e:
            D.choose_usable(infos, spec, env, build_error)
        assert broken in str(e.value) and "pocl-opencl-icd" in str(e.value) and "\n" not in str(e.value)
    fails[1] = "error: no compiler"
    with pytest.raises(DeviceError) as e:
        D.choose_usable(infos, None, {}, build_error)
    assert "0:0" in str(e.value) and "1:0" in str(e.value) and "Oclgrind" not in str(e.value)
    assert D.choose_usable(infos, "oclgrind", {}, build_error) == 2


def test_the_default_device_compiles(tmp_path, monkeypatch):
    """The device clcsg picks here builds a kernel (the probe is what selection relies on);
    built here, not answered from a record of an earlier process."""
    dev = D.select_device()
    monkeypatch.setenv("CLCSG_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(D, "_probe_results", {})
    built = []
    real = cl.Program

    def program(*args):
        built.append(args[1:])
        return real(*args)

    monkeypatch.setattr(cl, "Program", program)
    assert D._build_error(dev) is None
    assert built == [(D.PROBE_SOURCE,)]


def test_a_probed_device_is_remembered_per_driver(tmp_path, monkeypatch):
    """The probe's success is kept in the cache folder, under a name that changes with the
    device's and driver's versions; a later lookup in the process needs no build."""
    monkeypatch.setenv("CLCSG_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("CLCSG_NO_CACHE", raising=False)
    dev = D.select_device()
    mark = D._probe_mark(dev)
    assert mark is not None and mark.startswith(str(tmp_path))
    monkeypatch.setattr(D, "_probe_results", {})
    assert D._build_error(dev) is None and __import__("os").path.exists(mark)

    class Renamed:  # the same device after a driver update
        name, version, platform = dev.name, dev.version, dev.platform
        driver_version = dev.driver_version + "-next"

    assert D._probe_mark(Renamed()) not in (None, mark)
    monkeypatch.setenv("CLCSG_NO_CACHE", "1")
    assert D._probe_mark(dev) is None


def test_default_with_only_accelerator():
    infos = [info(0, 0, "cpu", oclgrind=True), info(1, 0, "accelerator", "FPGA", "fpga")]
    assert choose(infos, None, {}) == 1


def test_cpu_and_gpu_skip_oclgrind():
    assert choose(MIXED, "cpu", {}) == 1
    assert choose(MIXED, "GPU", {}) == 2
    assert choose(GRIND_FIRST, "cpu", {}) == 1
    with pytest.raises(DeviceError, match="'gpu'.*no GPU"):
        choose(GRIND_FIRST, "gpu", {})


def test_only_oclgrind_is_never_a_default():
    only = [info(0, 0, "cpu", oclgrind=True)]
    with pytest.raises(DeviceError, match="Oclgrind.*--device oclgrind"):
        choose(only, None, {})
    with pytest.raises(DeviceError, match="no CPU"):
        choose(only, "cpu", {})
    assert choose(only, "oclgrind", {}) == 0
    assert choose(only, "0:0", {}) == 0
    assert choose(only, None, {"PYOPENCL_CTX": "0:0"}) == 0


def test_oclgrind_by_name_index_or_env():
    assert choose(MIXED, "oclgrind", {}) == 0
    assert choose(MIXED, "0:0", {}) == 0
    assert choose(MIXED, "0", {}) == 0
    assert choose(MIXED, None, {"PYOPENCL_CTX": "0:0"}) == 0
    assert choose(MIXED, None, {"PYOPENCL_CTX": "oclgrind"}) == 0  # name substring, as in pyopencl
    with pytest.raises(DeviceError, match="'oclgrind'.*not installed"):
        choose(MIXED[1:], "oclgrind", {})


def test_indices_and_names():
    assert choose(MIXED, "2:1", {}) == 3
    assert choose(MIXED, "2", {}) == 2
    assert choose(MIXED, "nvidia:tesla", {}) == 3
    assert choose(MIXED, "portable", {}) == 1
    assert choose(MIXED, "2:", {}) == 2
    assert choose(MIXED, " 1:0 ", {}) == 1
    assert choose(MIXED, "", {}) == choose(MIXED, None, {})


def test_pyopencl_ctx():
    assert choose(MIXED, None, {"PYOPENCL_CTX": "1:0"}) == 1
    assert choose(MIXED, None, {"PYOPENCL_CTX": "2:1"}) == 3
    assert choose(MIXED, None, {"PYOPENCL_CTX": "2:0,1"}) == 2  # first of a device list
    assert choose(MIXED, None, {"PYOPENCL_CTX": ""}) == 2  # empty counts as unset
    # an explicit spec wins over the environment
    assert choose(MIXED, "cpu", {"PYOPENCL_CTX": "2:1"}) == 1
    with pytest.raises(DeviceError, match=r"PYOPENCL_CTX='7'.*platform index 7"):
        choose(MIXED, None, {"PYOPENCL_CTX": "7"})


@pytest.mark.parametrize(
    "spec, pattern",
    [
        ("tpu", r"unknown device 'tpu'.*cpu, gpu, oclgrind, P:D"),
        ("5:0", r"'5:0'.*platform index 5 is out of range \(valid: 0, 1, 2"),
        ("2:9", r"'2:9'.*device index 9 on platform 2 is out of range \(valid: 0, 1"),
        ("1:nope", r"'1:nope'.*no device on platform 1 matches 'nope'"),
        ("1:0:0", r"'1:0:0'.*expected P:D or P"),
        ("-1", r"'-1'.*out of range"),
    ],
)
def test_bad_specs(spec, pattern):
    with pytest.raises(DeviceError, match=pattern) as e:
        choose(MIXED, spec, {})
    assert "\n" not in str(e.value)
    assert e.value.exit_code == 4


def test_no_devices():
    with pytest.raises(DeviceError, match=r"no OpenCL platform found; install one with: pip install 'clcsg\[pocl\]'"):
        choose([], None, {})


def test_requirements_on_synthetic_info():
    weak = info(0, 0, "gpu", atomics=False, fp64=False)
    with pytest.raises(DeviceError, match="lacks cl_khr_int64_extended_atomics, needed by the splat renderer"):
        D.require_int64_atomics(weak, "the splat renderer")
    assert D.real_dtype(weak) == np.float32
    assert D.real_dtype(info(0, 0)) == np.float64


def test_no_platform_from_pyopencl(monkeypatch):
    """PLATFORM_NOT_FOUND_KHR from the ICD loader, or an empty list, is the install hint."""

    def raises():
        raise RuntimeError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", raises)
    with pytest.raises(DeviceError, match=r"^no OpenCL platform found; install one with"):
        D.list_devices()
    monkeypatch.setattr(cl, "get_platforms", lambda: [])
    with pytest.raises(DeviceError, match=r"^no OpenCL platform found"):
        D.select_device()


# -- the real installation ----------------------------------------------------------------------


def test_list_devices():
    infos = clcsg.devices()
    assert infos and infos == D.list_devices()
    for i in infos:
        assert isinstance(i, DeviceInfo)
        assert i.type in ("cpu", "gpu", "accelerator", "other")
        assert i.compute_units >= 1 and i.max_mem_alloc > 0 and i.global_mem >= i.max_mem_alloc
        assert isinstance(i.fp64, bool) and isinstance(i.int64_atomics, bool)
        assert i.is_oclgrind == ("oclgrind" in i.platform.lower())
        dev = cl.get_platforms()[i.platform_index].get_devices()[i.device_index]
        assert dev.name.strip() == i.name
    assert len({i.spec for i in infos}) == len(infos)


def _real_cpu():
    infos = D.list_devices()
    return next((i for i in infos if i.type == "cpu" and not i.is_oclgrind), None)


def test_select_cpu_and_index(monkeypatch):
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    cpu = _real_cpu()
    assert cpu is not None, "the test setup installs PoCL's CPU device (pip install '.[pocl]')"
    dev = D.select_device("cpu")
    assert isinstance(dev, cl.Device)
    assert dev == D.select_device(cpu.spec)
    assert dev.name.strip() == cpu.name
    first = D.list_devices()[0]
    assert D.select_device("0:0").name.strip() == first.name
    assert D.select_device("0") == D.select_device("0:0")


def _compiles(i):
    return D._build_error(cl.get_platforms()[i.platform_index].get_devices()[i.device_index]) is None


def test_select_follows_pyopencl_ctx(monkeypatch):
    infos = D.list_devices()
    last = [i for i in infos if _compiles(i)][-1]
    monkeypatch.setenv("PYOPENCL_CTX", last.spec)
    assert D.select_device().name.strip() == last.name
    monkeypatch.setenv("PYOPENCL_CTX", "99:0")
    with pytest.raises(DeviceError, match="PYOPENCL_CTX='99:0'"):
        D.select_device()
    # an explicit spec does not look at PYOPENCL_CTX
    first = [i for i in infos if _compiles(i)][0]
    assert D.select_device(first.spec).name.strip() == first.name


def test_default_selection_matches_rule(monkeypatch):
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    infos = D.list_devices()
    want = infos[D.choose_usable(infos, None, {}, lambda k: None if _compiles(infos[k]) else "fails")]
    assert not want.is_oclgrind
    assert D.select_device().name.strip() == want.name


@pytest.mark.parametrize("spec", ["tpu", "42:0", "0:42", "0:0:0"])
def test_select_bad_spec(spec):
    with pytest.raises(DeviceError) as e:
        D.select_device(spec)
    assert repr(spec) in str(e.value)


def test_get_context_is_cached(cl_context):
    assert isinstance(cl_context, D.Context)
    assert cl_context.device in cl_context.ctx.devices
    assert cl_context.queue.properties & cl.command_queue_properties.PROFILING_ENABLE
    again = D.get_context(cl_context.info.spec)
    assert again is cl_context
    assert D.real_dtype(cl_context) == (np.float64 if cl_context.info.fp64 else np.float32)


def test_context_runs_a_kernel(cl_context):
    prg = cl.Program(cl_context.ctx, "__kernel void twice(__global int *a) { a[get_global_id(0)] *= 2; }").build()
    a = np.arange(16, dtype=np.int32)
    buf = cl.Buffer(cl_context.ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=a)
    ev = prg.twice(cl_context.queue, a.shape, None, buf)
    ev.wait()
    assert ev.profile.end >= ev.profile.start  # profiling is on
    out = np.empty_like(a)
    cl.enqueue_copy(cl_context.queue, out, buf)
    assert (out == 2 * a).all()


def test_require_int64_atomics(cl_context):
    if cl_context.info.int64_atomics:
        D.require_int64_atomics(cl_context, "test")
    else:
        with pytest.raises(DeviceError, match="needed by test"):
            D.require_int64_atomics(cl_context, "test")


def test_vector_probe_passes_on_the_chosen_device():
    """The device the rule chose builds and runs the renderer's 8-wide vector math in the
    probe's child process (the check that passes over PoCL's wheel on AMD Zen 4)."""
    info = D.get_context().info
    assert D.vector_probe_error(info.platform_index, info.device_index) is None


def test_vector_probe_failure_is_one_line():
    """A child that fails (here: no such platform) gives a one-line reason, not a traceback."""
    why = D.vector_probe_error(99, 0)
    assert why is not None and why.startswith("its compiler fails on 8-wide vector math (")
    assert "\n" not in why and "IndexError" in why
