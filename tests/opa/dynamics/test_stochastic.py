"""The stochastic bifurcation diagram (opa.dynamics._stochastic): boundaries in xi against
the deterministic period doubling, against brute-force runs on both sides and (slow) the
scipy reference; probabilities against the law's CDF written out with scipy; Monte Carlo
agreement, also at the slow doubling near c = 0.09; the sampling fallback where
continuation cannot follow; coexisting attractors checked with scipy."""

import numpy as np
import pytest
from scipy import stats

from opa import SolverOptions, preset
from opa.dynamics._stochastic import classify, stochastic_diagram
from tests.reference import reference_trajectory

SECTION_31 = preset("3.1", F0=0.0)
#: the deterministic first-but-one period doubling of section 3.1 (F0 = 0) at mu = 0.8,
#: c = 0.0396996668 (docs/stability.md; located in c with mu fixed)
C_PD = 0.0396996668


def test_the_doubling_curve_passes_through_the_deterministic_point():
    """At c = C_PD the boundary in xi is the doubling at mu = 0.8, i.e. xi = 0 (issue
    27's target: within 1e-6), and under the semicircle each side has probability 1/2."""
    ds = stochastic_diagram(SECTION_31, "c", [C_PD], sigma=0.03, samples=0, extra_states=0)
    assert abs(float(ds.boundary_xi[0, 0])) < 1e-6
    assert str(ds.boundary_kind.values[0, 0]) == "period-doubling"
    assert list(ds.type.values) == ["2/2", "4/4"]
    np.testing.assert_allclose(ds.probability[0].values, [0.5, 0.5], atol=1e-6)


def test_probabilities_are_the_law_mass_between_the_boundaries():
    """beta:2,3: P(2/2) = F(xi*) with F the beta(2, 3) CDF on [-1, 1] (scipy, here)."""
    ds = stochastic_diagram(SECTION_31, "c", [0.04], sigma=0.03, samples=0,
                            distribution="beta:2,3", extra_states=0)
    xi_b = float(ds.boundary_xi[0, 0])
    F = stats.beta(2, 3, loc=-1, scale=2).cdf
    np.testing.assert_allclose(ds.probability.sel(type="2/2").values, [F(xi_b)], atol=1e-12)
    np.testing.assert_allclose(ds.probability.sel(type="4/4").values, [1 - F(xi_b)],
                               atol=1e-12)


def test_the_boundary_separates_what_long_brute_force_runs_see():
    """Independent of the continuation: runs of 4000 periods just below and above the
    located boundary settle on the two types it separates."""
    ds = stochastic_diagram(SECTION_31, "c", [0.04], sigma=0.03, samples=0, extra_states=0)
    mu_b = 0.8 + 0.03 * float(ds.boundary_xi[0, 0])
    osc = SECTION_31.replace(c=0.04)
    labels = classify(osc, "mu", [mu_b - 6e-4, mu_b + 6e-4], options=SolverOptions(),
                      transient=4000, record=64)
    assert labels == ["2/2", "4/4"]


def test_monte_carlo_agrees_on_a_smooth_case_and_near_a_doubling():
    ds = stochastic_diagram(SECTION_31, "c", [0.04, 0.07], sigma=0.03, samples=128,
                            extra_states=0)
    assert list(ds.agree.values) == [1, 1] and list(ds.method.values) == [0, 0]
    assert float(ds.probability.sel(c=0.07, type="2/2")) == 1.0
    assert float(ds.mc_probability.sel(c=0.07, type="2/2")) == 1.0
    # every sample on the side of the boundary its type belongs to, but those so near it
    # that their approach is still algebraic (a few 1e-3 in xi)
    xi, kinds = ds.mc_xi.sel(c=0.04).values, ds.mc_type.sel(c=0.04).values
    b = float(ds.boundary_xi.sel(c=0.04, boundary=0))
    far = np.abs(xi - b) > 0.02
    assert np.all((kinds[far] == "2/2") == (xi[far] < b))


def test_the_slow_doubling_near_c_009_is_continued_and_sampled_alike():
    """Section 3.1 at c = 0.0895, sigma = 0.05: the period-1 orbit doubles at xi =
    -0.392129 (continuation seeded by the grid's attractors). Over the whole support the
    orbits have a multiplier near -1, and runs from (x0, v0) look period-2 for hundreds of
    periods (a fixed 1000-period transient called them 2/2 everywhere); the approach test
    classifies them, and 128 samples agree with the law's mass on each side."""
    ds = stochastic_diagram(SECTION_31, "c", [0.0895], sigma=0.05, samples=128,
                            extra_states=0)
    assert int(ds.method[0]) == 0
    assert abs(float(ds.boundary_xi[0, 0]) + 0.392129) < 1e-5
    F = stats.semicircular.cdf  # the semicircle law on [-1, 1]
    np.testing.assert_allclose(float(ds.probability.sel(type="2/2")[0]),
                               F(float(ds.boundary_xi[0, 0])), atol=1e-12)
    assert int(ds.agree[0]) == 1


def test_where_continuation_cannot_follow_monte_carlo_decides():
    """c = 0.01: the samples are chaotic (exponent above the threshold): sampled."""
    ds = stochastic_diagram(SECTION_31, "c", [0.01], sigma=0.03, samples=64, extra_states=0)
    assert int(ds.method[0]) == 1
    assert "no periodic attractor" in str(ds.method_note.values[0])
    np.testing.assert_array_equal(ds.probability.values, ds.mc_probability.values)
    assert float(ds.probability.sel(type="chaotic").values[0]) > 0.9
    chaotic = ds.mc_type.values[0] == "chaotic"
    assert np.all(ds.mc_lyapunov.values[0][chaotic] > 0.01)


def test_coexisting_attractors_are_reported():
    """The paper's impulses (F0 = 0.1), c = 0.07, sigma = 0.01: the two 14T orbits of
    tests/opa/dynamics/test_attractor.py (checked there with scipy) coexist over the whole
    support; from the other initial states the interval's middle and the checked samples
    reach the other orbit, and the law mass whose attractor depends on the start is 1."""
    ds = stochastic_diagram(preset("3.1"), "c", [0.07], sigma=0.01, samples=8, coexist=8)
    assert "14/14 (another orbit)" in str(ds.interval_other.values[0, 0])
    assert float(ds.coexist_probability[0]) == pytest.approx(1.0)
    assert float(ds.mc_coexist[0]) > 0


@pytest.mark.parametrize("kw, message", [
    (dict(sigma=0.0), "sigma must be a positive number"),
    (dict(sigma=0.03, samples=1), "samples must be 0 or an integer >= 2"),
    (dict(sigma=0.03, uncertain="a1"), "uncertain must be one of mu, a, c, eta, delta, f"),
    (dict(sigma=0.03, extra_states=-1), "extra_states must be an integer >= 0"),
    (dict(sigma=0.03, workers=0), "workers must be an integer >= 1"),
    (dict(sigma=0.03, emr="yes"), "emr must be True or False"),
    (dict(sigma=0.03, emr=True, distribution="uniform"), "emr: the EMR"),
    (dict(sigma=0.03, record=2), "record must be >= 4"),
])
def test_bad_arguments_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        stochastic_diagram(SECTION_31, "c", [0.04], **kw)
    with pytest.raises(ValueError, match="parameter must be a model parameter other"):
        stochastic_diagram(SECTION_31, "mu", [0.8], sigma=0.03)


@pytest.mark.slow
def test_the_boundary_against_the_scipy_reference():
    """The scipy integrator (tests/reference.py), 1500 periods on each side of the
    located boundary: period 2 below it (x(kT) repeats every 2 periods), 4 above."""
    ds = stochastic_diagram(SECTION_31, "c", [0.04], sigma=0.03, samples=0, extra_states=0)
    mu_b = 0.8 + 0.03 * float(ds.boundary_xi[0, 0])
    model = {k: getattr(SECTION_31, k) for k in ("a", "f", "omega", "eta", "delta", "F0",
                                                  "a1", "omega1", "n", "x0", "v0")}
    T = 2 * np.pi / SECTION_31.omega
    t = np.arange(1501) * T
    for mu, repeat in ((mu_b - 3e-3, 2), (mu_b + 3e-3, 4)):
        x = reference_trajectory(mu=mu, c=0.04, t_out=t, **model)["x"][-16:]
        assert np.abs(x[repeat:] - x[:-repeat]).max() < 1e-6
        assert np.abs(x[repeat // 2:] - x[:-(repeat // 2)]).max() > 1e-3


def test_an_interrupted_diagram_resumes_from_its_parts(tmp_path, monkeypatch):
    """Each finished value is kept; a rerun computes only what is missing, and gives the
    same dataset. A damaged part is computed again."""
    import opa.dynamics._stochastic as S

    kw = dict(sigma=0.03, samples=8, transient=200, extra_states=1, coexist=4,
              parts=str(tmp_path / "parts"))
    first = stochastic_diagram(SECTION_31, "c", [0.04], **kw)
    calls = []
    original = S.compute_slice
    monkeypatch.setattr(S, "compute_slice",
                        lambda *a, **k: calls.append(1) or original(*a, **k))
    both = stochastic_diagram(SECTION_31, "c", [0.04, 0.05], **kw)
    assert len(calls) == 1  # 0.04 was read back
    np.testing.assert_array_equal(both.probability.sel(c=0.04).values,
                                  first.probability.sel(c=0.04).values)
    slices = sorted((tmp_path / "parts").glob("slice-*.npz"))
    assert len(slices) == 2
    for path in slices:
        path.write_bytes(b"not an archive")
    with pytest.warns(RuntimeWarning, match="is damaged") as caught:
        again = stochastic_diagram(SECTION_31, "c", [0.04, 0.05], **kw)
    assert len(calls) == 3 and len(caught) == 2
    assert all(path.with_name(path.name + ".bad").exists() for path in slices)
    np.testing.assert_array_equal(again.probability.values, both.probability.values)
    np.testing.assert_array_equal(again.mc_type.values, both.mc_type.values)


def test_an_execution_record_keeps_the_parts_where_its_checkpoint_says(tmp_path):
    """``execution=Execution(checkpoint=...)`` keeps the parts as ``parts=`` did and a
    rerun reads them back; ``parts`` beside an execution is refused by name."""
    from opa import Execution

    lines = []
    run = Execution(checkpoint=str(tmp_path / "kept"), log=lines.append)
    kw = dict(sigma=0.03, samples=8, transient=200, extra_states=0)
    first = stochastic_diagram(SECTION_31, "c", [0.04], execution=run, **kw)
    assert len(list((tmp_path / "kept").glob("slice-*.npz"))) == 1
    again = stochastic_diagram(SECTION_31, "c", [0.04], execution=run, **kw)
    assert any("read back" in line for line in lines)
    np.testing.assert_array_equal(again.probability.values, first.probability.values)
    with pytest.raises(ValueError, match=r"execution: give parts inside it"):
        stochastic_diagram(SECTION_31, "c", [0.04], execution=run,
                           parts=str(tmp_path / "other"), **kw)
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'progress'"):
        stochastic_diagram(SECTION_31, "c", [0.04], progress=False, **kw)


def test_the_records_give_the_keywords_diagram():
    """A System holding its uncertainty, ``settle=Settings(...)`` and ``emr=EMR(order)``
    give the keywords' diagram to the bit; a keyword beside its record is refused, and an
    Oscillator without ``sigma`` names it."""
    from opa import System
    from opa.dynamics._attractor import Settings
    from opa.dynamics._stochastic import EMR

    osc = preset("3.1", F0=0.0)
    kw = dict(samples=8, extra_states=0)
    by_keywords = stochastic_diagram(osc, "c", [0.035, 0.04], sigma=0.03, transient=200,
                                     emr=True, emr_order=2, **kw)
    by_records = stochastic_diagram(System(osc, sigma=0.03), "c", [0.035, 0.04],
                                    settle=Settings(transient=200), emr=EMR(order=2), **kw)
    for name in by_keywords.variables:
        np.testing.assert_array_equal(by_keywords[name].values, by_records[name].values,
                                      err_msg=name)
    with pytest.raises(ValueError, match=r"settle: give transient inside it"):
        stochastic_diagram(osc, "c", [0.04], sigma=0.03, settle=Settings(), transient=10)
    with pytest.raises(ValueError, match=r"emr: give emr_order inside EMR"):
        stochastic_diagram(osc, "c", [0.04], sigma=0.03, emr=EMR(), emr_order=3)
    with pytest.raises(ValueError, match=r"sigma is required with an opa.Oscillator"):
        stochastic_diagram(osc, "c", [0.04])


def test_a_dask_cluster_gives_the_same_diagram():
    """The control values as tasks on a LocalCluster of 2 worker processes: every
    variable the same as in this process, to the bit."""
    distributed = pytest.importorskip("distributed")
    kw = dict(sigma=0.03, samples=8, transient=200, extra_states=1, coexist=4)
    here = stochastic_diagram(SECTION_31, "c", [0.04, 0.05], **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        there = stochastic_diagram(SECTION_31, "c", [0.04, 0.05],
                                   scheduler=cluster.scheduler_address, **kw)
    from tests.compare.test_scaleout import assert_same_variables

    # but the CPU time each value took
    assert_same_variables(here, there, skip=[n for n in here.data_vars if "seconds" in n])


# ---------------------------------------------------------------- several uncertain parameters
#: mu and a uncertain at section 3.1 (F0 = 0): the doubling 2/2 -> 4/4 at c = C_PD moves
#: with a (xi_mu* = -0.35 at a = 0.998, 0 at a = 1, +0.36 at a = 1.002)
SEVERAL = dict(uncertain="mu,a", sigma=(0.03, 0.002), distribution="semicircle,uniform")


@pytest.fixture(scope="module")
def several():
    from opa import System

    system = System(SECTION_31, **SEVERAL)
    return stochastic_diagram(system, "c", [C_PD, 0.05], samples=128, extra_states=1,
                              coexist=8)


def _boundary_in_mu(a: float, c: float) -> tuple[float, float]:
    """(xi_mu* of the doubling, P(2/2)) of the one-parameter diagram at a fixed a: the
    boundary by continuation in mu alone, its probability the semicircle's CDF there."""
    ds = stochastic_diagram(SECTION_31.replace(a=a), "c", [c], sigma=0.03, samples=0,
                            extra_states=0)
    xi = ds.boundary_xi.values[0]
    p = float(ds.probability.sel(type="2/2")[0]) if "2/2" in ds.type.values else 0.0
    return (float(xi[0]) if len(xi) and np.isfinite(xi[0]) else np.nan), p


def test_several_parameters_probabilities_against_the_one_dimensional_boundaries(several):
    """(mu, a) uncertain: P(2/2) at c = C_PD is the law's mass below the boundary curve
    xi_mu*(xi_a), computed independently as a 6-point Gauss-Legendre rule over the
    uniform xi_a of the one-parameter diagrams' exact conditional probabilities
    (continuation in mu at each node, the semicircle's CDF there); the sampled share lies
    within 3 standard errors (+ one sample) of it, and every sample farther than 0.02 in
    xi_mu from the curve has the type of its side. At c = 0.05 every sample is 2/2:
    probability 1, SE 0, as the one-parameter diagrams at both ends of a say."""
    ds = several
    nodes, weights = np.polynomial.legendre.leggauss(6)
    found = [_boundary_in_mu(1.0 + 0.002 * x, C_PD) for x in nodes]
    reference = float(np.sum(weights / 2 * [p for _, p in found]))
    p = float(ds.probability.sel(c=C_PD, type="2/2"))
    se = float(ds.mc_sem.sel(c=C_PD, type="2/2"))
    assert 0 < se < 0.05 and abs(p - reference) <= 3 * se + 1 / 128, (p, se, reference)
    curve = np.polynomial.polynomial.Polynomial.fit(nodes, [x for x, _ in found], 5)
    xi = ds.mc_xi.values
    below = xi[:, 0] < curve(xi[:, 1])
    far = np.abs(xi[:, 0] - curve(xi[:, 1])) > 0.02
    types = ds.mc_type.sel(c=C_PD).values
    assert far.sum() > 100
    assert np.all((types[far] == "2/2") == below[far])
    assert np.all(np.isin(types, ["2/2", "4/4"]))
    # c = 0.05: the whole law is 2/2
    assert [p for _, p in (_boundary_in_mu(a, 0.05) for a in (0.998, 1.002))] == [1.0, 1.0]
    assert float(ds.probability.sel(c=0.05, type="2/2")) == 1.0
    assert float(ds.mc_sem.sel(c=0.05, type="2/2")) == 0.0
    assert float(ds.probability.sel(c=0.05, type="4/4")) == 0.0


def test_several_parameters_dataset_says_why_there_are_no_boundaries(several):
    ds = several
    assert ds.mc_xi.dims == ("sample", "parameter") and ds.sizes["sample"] == 128
    assert list(ds.parameter.values) == ["mu", "a"]
    assert ds.attrs["uncertain"] == "mu,a" and list(ds.attrs["sigma"]) == [0.03, 0.002]
    assert ds.attrs["distribution"] == "semicircle,uniform"
    assert "one-dimensional by nature" in ds.attrs["boundaries"]
    assert "boundary_xi" not in ds and "interval_type" not in ds
    assert list(ds.method.values) == [1, 1] and list(ds.agree.values) == [-1, -1]
    np.testing.assert_array_equal(ds.probability.values, ds.mc_probability.values)
    assert ds.attrs["scramblings"] == 8 and ds.attrs["coexist_samples"] == 8
    # the points are the problem's scrambled Sobol' points, within its support
    assert np.all(np.abs(ds.mc_xi.values) <= 1.0)
    assert np.isfinite(ds.mc_coexist.values).all()


@pytest.mark.parametrize("kw, message", [
    (dict(emr=True), r"^emr: the EMR's sweep takes one uncertain parameter; this diagram "
                     r"has 2 \(mu,a\)"),
    (dict(xtol=1e-8), r"^xtol 1e-08 has no effect with 2 uncertain parameters"),
    (dict(samples=100), r"^samples must be a multiple of 8 and at least 16"),
    (dict(samples=0), r"^samples must be a multiple of 8"),
    (dict(sigma=(0.03, 0.002, 0.1)), r"^sigma must give one value, or one per"),
    (dict(sigma=(0.9, 0.002)), r"^sigma 0.9 makes mu = 0.8 \+ sigma xi negative"),
    (dict(distribution="semicircle,foo"), r"^distribution"),
    (dict(parameter="a"), r"^parameter must be a model parameter other than the "
                          r"uncertain ones \(mu,a\)"),
])
def test_several_parameters_refuse_what_is_one_dimensional_by_name(kw, message):
    keywords = {**SEVERAL, "samples": 16, **kw}
    parameter = keywords.pop("parameter", "c")
    with pytest.raises(ValueError, match=message):
        stochastic_diagram(SECTION_31, parameter, [0.05], **keywords)


def test_several_parameters_resume_from_their_parts(tmp_path, monkeypatch):
    """A removed part is computed again, the dataset is the same; a changed problem
    (another sigma of a) is not resumed from."""
    import opa.dynamics._stochastic as S

    kw = dict(**SEVERAL, samples=16, transient=200, extra_states=0,
              parts=str(tmp_path / "parts"))
    first = stochastic_diagram(SECTION_31, "c", [C_PD, 0.05], **kw)
    parts = sorted((tmp_path / "parts").glob("slice-*.npz"))
    assert len(parts) == 2
    parts[0].unlink()
    calls = []
    original = S.compute_slice
    monkeypatch.setattr(S, "compute_slice",
                        lambda *a, **k: calls.append(1) or original(*a, **k))
    again = stochastic_diagram(SECTION_31, "c", [C_PD, 0.05], **kw)
    assert len(calls) == 1
    for name in ("probability", "mc_sem", "mc_type", "mc_xi", "mc_x"):
        np.testing.assert_array_equal(again[name].values, first[name].values)
    other = stochastic_diagram(SECTION_31, "c", [C_PD, 0.05],
                               **{**kw, "sigma": (0.03, 0.003)})
    assert len(calls) == 3
    assert list(other.attrs["sigma"]) == [0.03, 0.003]


@pytest.mark.parametrize("uncertain, sigma", [("omega", 0.001), ("mu,omega", (0.01, 0.001))])
def test_an_uncertain_omega_is_refused_naming_why(uncertain, sigma):
    """Each sampled system's period differs from the nominal one at which its attractor
    is classified: with sigma = 1e-4 a stable period-1 orbit read as quasi-periodic in
    10 of 16 samples of Shaw & Holmes' (zeta = 0.05; measured before the refusal);
    refused in one line."""
    with pytest.raises(ValueError, match=r"^uncertain omega: omega cannot be uncertain") as err:
        stochastic_diagram(SECTION_31, "c", [0.05], uncertain=uncertain, sigma=sigma,
                           samples=16)
    assert "\n" not in str(err.value)


def test_a_user_laws_constant_is_the_control_parameter():
    """Shaw & Holmes' damping zeta as the control parameter, eta uncertain: the stable
    closed-form period-1 orbit holds the whole law (``tests/impact_truths.py``: |mu| <
    0.73 at zeta = 0.04 and 0.05)."""
    import opa

    osc = opa.Oscillator(force=opa.ForceLaw("-2*zeta*v - x", zeta=0.05), f=1.0, omega=2.5,
                         eta=0.8, delta=0.0, F0=0.0, omega1=2.5, x0=-0.5)
    ds = stochastic_diagram(osc, "zeta", [0.04, 0.05], uncertain="eta", sigma=0.005,
                            samples=16, extra_states=0, transient=300, record=16)
    assert ds.zeta.values.tolist() == [0.04, 0.05]
    labels = [str(t) for t in np.atleast_1d(ds.type.values).ravel() if str(t)]
    assert set(labels) >= {"1/1"}, labels
    np.testing.assert_allclose(ds.probability.sel(type="1/1").values, 1.0)
