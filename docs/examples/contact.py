"""Force laws as Python functions, for ``function = "contact:NAME"`` in a model file (or
``opa.ForceLaw.from_function``): g(x, v, constant, ...), compiled by numba."""


def hertz(x, v, zeta, k, g):
    """A linear oscillator with a Hertzian contact spring k max(x - g, 0)^1.5."""
    return -2.0 * zeta * v - x - k * max(x - g, 0.0) ** 1.5
