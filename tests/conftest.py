"""Helpers shared by the test modules."""

from opa._system import as_system


def kernel_inputs(oscillator, options, **fields):
    """The kernel's inputs (``opa._run.Inputs``) of ``System(oscillator, **fields)``, with
    the DMR's defaults (sigma 0, N 0) for the fields not given: for the tests that call the
    compiled kernel itself."""
    return as_system(oscillator, options, **{"sigma": 0.0, "order": 0, **fields}) \
        .kernel_inputs(options)


def rule(inputs):
    """The node-major Gauss rule of ``inputs``: (nodes, weights, basis)."""
    return inputs.table, inputs.weights, inputs.basis
