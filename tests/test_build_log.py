"""A program whose build log is not empty prints nothing on a normal run (pyopencl's
CompilerWarning and the driver's diagnostics stay off stderr), and the log is found with
GPISCL_BUILD_LOG=1."""
import os
import subprocess
import sys

SCRIPT = r'''
from gpiscl.host.render.device import Device, build_quietly
dev = Device()
# a #warning puts a line in the build log on every OpenCL C compiler; the random comment
# keeps the driver's binary cache from answering without a compile
import random
src = '#warning "probe %d"\n__kernel void k(__global int *a) { a[0] = 1; }' % random.getrandbits(48)
prg = build_quietly(dev, src, [])
assert prg.get_build_info(dev.device, __import__("pyopencl").program_build_info.LOG).strip()
'''


def run(extra_env):
    env = {**os.environ, **extra_env}
    env.pop("PYOPENCL_COMPILER_OUTPUT", None)
    return subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                          env=env, timeout=300)


def test_a_build_with_a_log_prints_nothing():
    out = run({})
    assert out.returncode == 0, out.stderr
    assert out.stderr == "" and out.stdout == ""


def test_the_build_log_is_kept_on_request():
    out = run({"GPISCL_BUILD_LOG": "1"})
    assert out.returncode == 0, out.stderr
    line, = out.stderr.splitlines()
    path = line.rsplit(" in ", 1)[1]
    try:
        assert "probe" in open(path).read()
    finally:
        os.unlink(path)
