"""`hydrojet-bench warmup` reaches every kernel, so that no later command compiles one."""

import subprocess
import sys

# Run in a fresh interpreter: in this one, other tests may already have called the
# kernels, and the check could not fail.
_CHECK = """
import importlib, inspect
from numba.core.registry import CPUDispatcher
from hydrojet_bench.cli import main

assert main(["warmup"]) == 0
called = []
for module_name in {modules!r}:
    module = importlib.import_module(module_name)
    for name, kernel in vars(module).items():
        # A kernel only other kernels call has no signature of its own here: its callers
        # came from the cache with it inside. Those called from Python have one.
        if not isinstance(kernel, CPUDispatcher) or kernel.__module__ != module_name or not kernel.signatures:
            continue
        called.append(name)
        parameters = list(inspect.signature(kernel.py_func).parameters)
        if "beta" in parameters:
            # Both the plain rod's variant (beta None) and the general rod's.
            kinds = {{str(signature[parameters.index("beta")]) for signature in kernel.signatures}}
            if not {{"none", "float64"}} <= kinds:
                print(f"only beta {{sorted(kinds)}}: {{module_name}}.{{name}}")
print(" ".join(sorted(called)))
"""

KERNEL_MODULES = ("hydrojet_bench.models.kernels", "hydrojet_bench.estimation.online", "hydrojet_bench.geometry",
                  "hydrojet_bench.twin.settling", "drivers.imu.emulator", "drivers.aurora.crc")


def test_warmup_says_what_it_does_and_compiles_every_kernel_and_both_variants_of_the_rods():
    done = subprocess.run([sys.executable, "-c", _CHECK.format(modules=KERNEL_MODULES)], capture_output=True,
                          text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert done.stderr.startswith("compiling the kernels")
    assert "the prb model with every library effect" in done.stderr
    assert "kernels ready in" in done.stderr.splitlines()[-1]
    *complaints, called = done.stdout.splitlines()
    assert complaints == []
    # The entry points of the solves, the sensitivities, the online update, the twin's
    # settling law and the emulators' sampling.
    assert {"solve_from", "solve_batch", "tip_wrench_sensitivity", "tip_wrench_sensitivity_batch", "body_twist",
            "_update_kernel", "settling_states_into", "_fifo_run", "_crc16_of_bytes"} <= set(called.split())

