"""The bench's model: sampled against continuous, static gains against hand formulas, the loop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import cont2discrete

from indsim import HV, IndBench, bench_model
from indsim.control import CL_INPUTS, CL_OUTPUTS, seed_controller_tf
from indsim.lti import simulate
from indsim.plant import INPUTS, OUTPUTS, build_plant, sample_plant


def _poisson_sampled(plant, i_in, i_out, f, T, delay, images=1500):
    """Sampled response by Poisson's sum over the continuous one (ZOH pulse and delay).

    The partial sums over ``|m| <= M`` and ``<= 2M`` are extrapolated as
    ``2 S(2M) - S(M)``: a path of relative degree 1 (``Uc -> Vc``) has a tail
    falling as ``1/M``, the others faster.
    """
    return 2 * _poisson_partial(plant, i_in, i_out, f, T, delay, 2 * images) - _poisson_partial(
        plant, i_in, i_out, f, T, delay, images)


def _poisson_partial(plant, i_in, i_out, f, T, delay, images):
    """Poisson's partial sum over ``|m| <= images``."""
    lam, V = np.linalg.eig(plant.A)
    cv = plant.C[i_out] @ V
    vb = np.linalg.solve(V, plant.B[:, i_in])
    m = np.arange(-images, images + 1)
    out = []
    for fk in f:
        w = 2 * np.pi * (fk + m / T)
        s = 1j * w
        H = (cv * vb) @ (1.0 / (s[None, :] - lam[:, None]))
        pulse = (1 - np.exp(-s * T)) / s
        out.append(np.sum(H * pulse * np.exp(-s * delay)) / T)
    return np.array(out)


@pytest.mark.parametrize("name", ["plain", "delay_split", "qd_amp2_5k", "back_emf", "fs5k"])
@pytest.mark.parametrize("path", [("Uch", "Vph"), ("Ucv", "Vpv"), ("Unh", "Vph"),
                                  ("Uch", "Vch")])
def test_sampled_model_is_the_continuous_one_behind_hold_and_delay(benches, name, path):
    """Discrete response = (1/T) sum_m G(j w_m) P(j w_m) e^{-j w_m D} (Poisson), w_m = w + m ws."""
    b = benches[name]
    plant = build_plant(b)
    sp = sample_plant(plant, b.dt_s)
    j, o = INPUTS.index(path[0]), OUTPUTS.index(path[1])
    f = np.array([7.0, 97.0, 0.98 * b.sercalo_resonance_hz.v, 410.0, 0.3 * b.fs_hz])
    z = np.exp(2j * np.pi * f * b.dt_s)
    n = int(sp.n_whole[j])
    Hd = np.array([sp.system.C[o] @ np.linalg.solve(zk * np.eye(len(sp.Phi)) - sp.Phi,
                                                     sp.Gb[:, j] * zk ** -n
                                                     + sp.Ga[:, j] * zk ** (-n - 1))
                   for zk in z])
    ref = _poisson_sampled(plant, j, o, f, b.dt_s, plant.delays_s[j])
    # The extrapolated sum's error is O(1/M^2) ~ 4e-7 for relative degree 1 (Uc -> Vc),
    # far less for the others.
    np.testing.assert_allclose(Hd, ref, rtol=2e-6)


def test_static_gains_by_hand():
    """The static paths against the study's formulas (2.1-2.4) on a plain-like bench."""
    b = IndBench(r_series_ohm=HV(12.0, 7.0), qd_polarity=HV(1.0, -1.0))
    G = build_plant(b).dc_gain()
    o, i = OUTPUTS.index, INPUTS.index
    gi = [1 / (41 + 12 + 9.3), 1 / (41 + 7 + 8.3)]
    # Ich -> Vph = p g (mount 4) G0; Uc -> Vc = 1000 Rc Gi; Unh -> Vph = p g 2 gn.
    # Exact formulas: approx's default 1e-6 relative covers the solve's rounding.
    assert G[o("Vph"), i("Uch")] == pytest.approx(31.0 * -4 * b.sercalo_gain_rad_per_a.h * gi[0])
    assert G[o("Vpv"), i("Ucv")] == pytest.approx(-36.3 * 4 * b.sercalo_gain_rad_per_a.v * gi[1])
    assert G[o("Vch"), i("Uch")] == pytest.approx(1000 * 9.3 * gi[0])
    assert G[o("Vcv"), i("Ucv")] == pytest.approx(1000 * 8.3 * gi[1])
    assert G[o("Vph"), i("Unh")] == pytest.approx(31.0 * 2 * 2.62e-3)
    assert G[o("Vpv"), i("Unv")] == pytest.approx(-36.3 * 2 * 2.62e-3)
    assert G[o("Vpv"), i("Uch")] == 0.0 and G[o("Vph"), i("Unv")] == 0.0


def test_rotation_and_crosstalk_cross_paths():
    """A turned 4QD mixes the axes by sin θ; torque crosstalk drives the other mode statically."""
    th, c = 0.03, 0.02
    b = IndBench(qd_rotation_rad=th, sercalo_torque_crosstalk=HV(c, 0.0))
    G = build_plant(b).dc_gain()
    o, i = OUTPUTS.index, INPUTS.index
    # Exact formulas (default 1e-6 relative). Vpv = p_v g_v (-sin θ b_x + cos θ b_y).
    assert G[o("Vpv"), i("Unh")] == pytest.approx(36.3 * -math.sin(th) * 2 * 2.62e-3)
    assert G[o("Vph"), i("Unh")] == pytest.approx(-31.0 * math.cos(th) * 2 * 2.62e-3)
    # Coil h's torque about b: static phi_b = c G0_v Ich.
    gi = 1 / (41 + 9.3)
    assert G[o("phi_b"), i("Uch")] == pytest.approx(c * b.sercalo_gain_rad_per_a.v * gi)


def test_modes_and_back_emf_damping():
    """Poles at the parameters; back-EMF adds about G0 w0 k_e / (2 R_tot) of damping."""
    b = IndBench(back_emf_v_s_per_rad=HV(6e-5, 0.0))
    lam = np.linalg.eigvals(build_plant(b).A)

    def nearest(f):
        w = 2 * np.pi * f
        return lam[np.argmin(np.abs(lam - 1j * w))]

    pv = nearest(b.sercalo_resonance_hz.v)
    assert abs(pv) / (2 * np.pi) == pytest.approx(b.sercalo_resonance_hz.v, rel=1e-9)
    assert -pv.real / abs(pv) == pytest.approx(b.sercalo_damping_ratio.v, rel=1e-6)
    ph = nearest(b.sercalo_resonance_hz.h)
    w0, r = 2 * np.pi * b.sercalo_resonance_hz.h, b.r_total_ohm.h
    added = b.sercalo_gain_rad_per_a.h * w0 * 6e-5 / (2 * r)
    # The coil's inductance (wL/R = 5 %) bends the first-order estimate by a few percent.
    assert -ph.real / abs(ph) - b.sercalo_damping_ratio.h == pytest.approx(added, rel=0.1)


def _loop_reference(bench, model, w):
    """The closed loop written as a per-sample program: plant recursion, DAC registers,
    controllers as Tustin difference equations of Kh, Kv (tf form)."""
    sp = sample_plant(build_plant(bench, with_vc=False), bench.dt_s)
    n_c = int(sp.n_whole[0])
    ctrl = []
    for ax in ("h", "v"):
        num, den = seed_controller_tf(ax)
        bd, ad, _ = cont2discrete((num, den), bench.dt_s, method="bilinear")
        ctrl.append((np.ravel(bd) / ad[0], np.asarray(ad) / ad[0]))
    mu = [model.closed.multiplier.h, model.closed.multiplier.v]
    gd = [model.gd_v_per_rad.h, model.gd_v_per_rad.v]
    N = len(w)
    x = np.zeros(len(sp.Phi))
    u_hist = np.zeros((N + n_c + 2, 2))  # u_hist[k + n_c + 1] = u[k]
    r_hist = [np.zeros(N), np.zeros(N)]
    k_hist = [np.zeros(N), np.zeros(N)]
    col = {name: w[:, CL_INPUTS.index(name)] for name in CL_INPUTS}
    y_out = np.zeros((N, 2))
    u_out = np.zeros((N, 2))
    for k in range(N):
        vp = sp.system.C[0:2] @ x
        y_out[k] = vp
        for j, ax in enumerate(("h", "v")):
            r_hist[j][k] = (vp[j] + col[f"qd_noise_{ax}"][k] + col[f"adc_{ax}"][k]) / gd[j]
            bk, ak = ctrl[j]
            acc = sum(bk[i] * r_hist[j][k - i] for i in range(len(bk)) if k - i >= 0)
            acc -= sum(ak[i] * k_hist[j][k - i] for i in range(1, len(ak)) if k - i >= 0)
            k_hist[j][k] = acc
            u_out[k, j] = -mu[j] * acc
            u_hist[k + n_c + 1, j] = u_out[k, j] + col[f"dac_{ax}"][k]
        uc_now = u_hist[k + 1]  # u[k - n_c]
        uc_prev = u_hist[k]  # u[k - n_c - 1]
        x = (sp.Phi @ x + sp.Gb[:, 0:2] @ uc_now + sp.Ga[:, 0:2] @ uc_prev
             + sp.Gb[:, 2] * col["Unh_d"][k] + sp.Gb[:, 3] * col["Unv_d"][k]
             + sp.Gb[:, 4] * col["nu_a"][k] + sp.Gb[:, 5] * col["nu_b"][k]
             + sp.Ga[:, 2] * col["Unh_d1"][k] + sp.Ga[:, 3] * col["Unv_d1"][k])
    return y_out, u_out


@pytest.mark.parametrize("name", ["plain", "weak", "delay_split", "fs20k"])
def test_closed_loop_system_is_the_loop_program(benches, name):
    """The one-system closed loop against the loop written sample by sample."""
    b = benches[name]
    model = bench_model(b)
    rng = np.random.default_rng(2)
    N = 1500
    w = rng.standard_normal((N, len(CL_INPUTS))) * 1e-3
    y = simulate(model.closed.system, w)
    y_ref, u_ref = _loop_reference(b, model, w)
    k = CL_OUTPUTS.index("Uch")
    # Two realisations of the same linear recursion: rounding only (1e-9 of the signals).
    np.testing.assert_allclose(y[:, 0:2], y_ref, rtol=0, atol=1e-9 * np.abs(y_ref).max())
    np.testing.assert_allclose(y[:, k:k + 2], u_ref, rtol=0, atol=1e-9 * np.abs(u_ref).max())


@pytest.mark.parametrize("name", ["plain", "qd_amp1_2k", "qd_amp2_5k", "delay_split", "fs20k",
                                  "fs5k", "newport_underdamped"])
def test_truth_effective_delays_are_the_sampled_phase(benches, name):
    """The truth's effective delays are the low-frequency phase of the sampled paths once the
    Sercalo's mode (or the Newport's second order) and the sign are taken out."""
    from indsim.truth import truth

    b = benches[name]
    model = bench_model(b)
    t = truth(model)
    sp = model.sampled
    f = np.array([5.0, 10.0, 20.0])
    z = np.exp(2j * np.pi * f * b.dt_s)
    for inp, out, f0, z0, key in (
        ("Uch", "Vph", b.sercalo_resonance_hz.h, b.sercalo_damping_ratio.h, "sercalo"),
        ("Unh", "Vph", b.newport_natural_freq_hz.h, b.newport_damping_ratio.h, "newport"),
    ):
        j, o = INPUTS.index(inp), OUTPUTS.index(out)
        n = int(sp.n_whole[j])
        H = np.array([sp.system.C[o] @ np.linalg.solve(zk * np.eye(len(sp.Phi)) - sp.Phi,
                                                        sp.Gb[:, j] * zk ** -n
                                                        + sp.Ga[:, j] * zk ** (-n - 1))
                      for zk in z])
        s = 2j * np.pi * f
        w0 = 2 * np.pi * f0
        second_order = w0 * w0 / (s * s + 2 * z0 * w0 * s + w0 * w0)
        lag = -np.angle(H / second_order / np.sign(H[0].real)) / (2 * np.pi * f)
        # Lags of 2-200 us at <= 20 Hz are linear in phase to (w tau)^2 < 1e-3; the hold's
        # aliased images add a slope of order (f0/fs)^2 T: 0.4 % for the Newport at 5 kHz.
        np.testing.assert_allclose(lag, t["effective_delay_s"][key], rtol=5e-3)


@pytest.mark.parametrize("bench_name", ["qd_amp2_5k", "qd_amp1_2k", "real_like"])
def test_compression_residual_passes_the_continuous_amplifier(benches, bench_name):
    """The cubic's residual equals the amplifier's ODE integrated on ``d(t)`` itself.

    Reference, independent of the FFT: ``d`` band-limited (below 1.5 kHz) is
    interpolated 32x by its own spectrum, cubed, and the amplifier's continuous
    state space integrated on that fine grid by scipy's ``lsim``; every 32nd
    sample is compared. A ZOH-sampled amplifier errs here by its half-sample lag
    (38 % of the residual's rms). The tolerance, 0.1 % of the residual's rms,
    is lsim's linear hold over 1/32 of a sample (7e-5 measured), with room for
    the periodic edge (the first and last 5 ms are left out).
    """
    from dataclasses import replace

    from scipy.signal import lsim, resample

    from indsim.experiments import _compression
    from indsim.model import bench_model

    bench = benches[bench_name]
    if bench.qd_compression == 0.0:
        bench = replace(bench, qd_compression=0.02)
    model = bench_model(bench)
    fs, n, up = bench.fs_hz, 4096, 32
    rng = np.random.default_rng(7)
    spec = np.fft.rfft(rng.standard_normal((n, 2)), axis=0)
    spec[np.fft.rfftfreq(n, 1 / fs) > 1500.0] = 0.0
    d = np.fft.irfft(spec, n=n, axis=0)
    d *= bench.qd_compression_swing_rad / 3.0 / d.std(axis=0)
    got = _compression(model, d)
    fine = resample(d, n * up, axis=0)  # exact for this periodic, band-limited d
    g = np.array([bench.qd_polarity.h * bench.qd_gain_v_per_rad.h,
                  bench.qd_polarity.v * bench.qd_gain_v_per_rad.v])
    r_fine = -g * bench.qd_cubic_per_rad2 * fine**3
    w = 2 * np.pi * bench.qd_amp_bandwidth_hz
    if bench.qd_amp_order == 1:
        amp = (np.array([[-w]]), np.array([[w]]), np.array([[1.0]]), np.array([[0.0]]))
    else:
        z = bench.qd_amp_damping_ratio
        amp = (np.array([[0.0, 1.0], [-w * w, -2 * z * w]]), np.array([[0.0], [w * w]]),
               np.array([[1.0, 0.0]]), np.array([[0.0]]))
    # Three periods so the ODE forgets its zero start; the last one is compared.
    ref = np.column_stack([lsim(amp, np.tile(r_fine[:, j], 3), np.arange(3 * n * up)
                               / (fs * up))[1][-n * up:][::up] for j in range(2)])
    edge = int(0.005 * fs)
    err = (got - ref)[edge:-edge]
    relative = np.sqrt(np.mean(err**2, axis=0) / np.mean(ref[edge:-edge] ** 2, axis=0))
    assert np.all(relative < 1e-3), relative
