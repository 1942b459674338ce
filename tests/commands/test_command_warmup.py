"""`hydrojet-bench warmup` reaches every kernel, so that no later command compiles one."""

import ast
import importlib
import inspect
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


def test_no_kernel_passes_a_literal_flag_to_another():
    # Numba compiles a callee once per literal argument value: `solve` called with a bare
    # True beside a bool, and `shoot` with True and False, doubled the warm-up (198 s
    # against 116 s). `models.kernels` says to write np.bool_(True).
    from numba.core.registry import CPUDispatcher

    literal_calls = []
    for module_name in KERNEL_MODULES:
        module = importlib.import_module(module_name)
        for name, kernel in vars(module).items():
            if not isinstance(kernel, CPUDispatcher) or kernel.__module__ != module_name:
                continue
            for call in ast.walk(ast.parse(inspect.getsource(kernel.py_func))):
                if not isinstance(call, ast.Call) or not isinstance(
                        _resolve(call.func, vars(module)), CPUDispatcher):
                    continue
                arguments = [*call.args, *(keyword.value for keyword in call.keywords)]
                if any(isinstance(argument, ast.Constant) and isinstance(argument.value, bool)
                       for argument in arguments):
                    literal_calls.append(f"{module_name}.{name}: {ast.unparse(call)[:100]}")
    assert literal_calls == []


def _resolve(expression: ast.expr, namespace: dict):
    """The object a called name (``solve``) or attribute (``kernels.solve``) names, or None."""
    if isinstance(expression, ast.Name):
        return namespace.get(expression.id)
    if isinstance(expression, ast.Attribute):
        return getattr(_resolve(expression.value, namespace), expression.attr, None)
    return None
