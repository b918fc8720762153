"""The engine's loop as one linear system: what an excitation does with the loop closed.

:func:`closed_loop_plant` closes the engine's sampled plant
(:func:`fsmbench.sim.plant.bench_discrete`) with a
:class:`~fsmbench.sim.engine.DiscreteController` exactly as the compiled loop
orders a sample (:mod:`fsmbench.sim.engine`): the ADC reads ``y[k] = C z[k]``,
the controller commands ``u[k] = c x[k] + d (y[k] - r[k])`` on its DAC
channels, the excitations ``w[k]`` are added to the commands, and the plant
advances with the sum. Converters are ideal (no quantisation, no rails) and the
4QD linear: this is the linear part the engine's nonlinearities sit on, the
same model :func:`fsmbench.sim.controller.closed_loop_spectral_radius` checks
the stability of.

The result is a :class:`~fsmbench.sim.discretize.DiscretePlant` with

* inputs: the four DAC channels (an excitation added to a command, e.g.
  ``Uch``) and one reference per controller input, named ``ref_<ADC channel>``
  (``ref_Vph``: a voltage the loop makes the 4QD reading follow) [V];
* outputs: the plant's (ADC channels [V], internal angles [rad]), then
  ``fb_<DAC channel>``, the controller's part of each command it drives [V]
  (the command the DAC receives is that plus the excitation on the channel).

It has no direct feedthrough from its inputs (a command acts on the plant
from the next sample), so the excitation tools' responses
(:func:`fsmbench.excite.limits.response_from_rest`) apply to it unchanged.
"""

from __future__ import annotations

import numpy as np

from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS

__all__ = ["closed_loop_plant", "feedback_name", "reference_feedthrough", "reference_name"]


def reference_name(adc_channel: str) -> str:
    """Input name of the reference on an ADC channel the controller reads (``ref_Vph``)."""
    return f"ref_{adc_channel}"


def feedback_name(dac_channel: str) -> str:
    """Output name of the controller's part of a command (``fb_Uch``)."""
    return f"fb_{dac_channel}"


def reference_feedthrough(controller: DiscreteController) -> np.ndarray:
    """Direct term from the references to the ``fb_`` outputs, ``-d`` [V/V], (n_out, n_in).

    A reference acts on the command in the same sample through the controller's
    ``d``; :func:`closed_loop_plant`'s state-space outputs leave it out.
    """
    return -np.asarray(controller.d, dtype=float)


def closed_loop_plant(plant: DiscretePlant, controller: DiscreteController, *,
                      n_adc: int = len(ADC_CHANNELS)) -> DiscretePlant:
    """``plant`` closed by ``controller`` as the engine closes it (see the module notes).

    Parameters
    ----------
    plant : DiscretePlant
        The engine's plant: inputs :data:`~fsmbench.sim.plant.DAC_CHANNELS`,
        its first ``n_adc`` outputs the ADC channels.
    controller : DiscreteController
        Wired as in the engine (sign and 4QD scaling folded in).
    n_adc : int
        Number of ADC channels among the plant's outputs.

    Returns
    -------
    DiscretePlant
        States ``[z; x]`` (plant, then controller); inputs the DAC channels then
        ``ref_<channel>`` per controller input; outputs the plant's then
        ``fb_<channel>`` per controller output. ``n_plant_states`` is the whole
        state (every state is a dynamic one of the loop).

    Raises
    ------
    ValueError
        The controller reads a channel that is not an ADC channel, or drives one
        the plant has no input for.
    """
    a, b, c = plant.a, plant.b, plant.c
    nz, nk = a.shape[0], controller.a.shape[0]
    if max(controller.adc_inputs, default=-1) >= n_adc:
        raise ValueError(f"the controller reads channel {max(controller.adc_inputs)}, the plant "
                         f"has {n_adc} ADC channels")
    if max(controller.dac_outputs, default=-1) >= b.shape[1]:
        raise ValueError(f"the controller drives input {max(controller.dac_outputs)}, the plant "
                         f"has {b.shape[1]}")
    n_in, n_out = len(controller.adc_inputs), len(controller.dac_outputs)
    sel_in = np.zeros((n_in, n_adc))
    sel_in[np.arange(n_in), controller.adc_inputs] = 1.0
    sel_out = np.zeros((b.shape[1], n_out))
    sel_out[controller.dac_outputs, np.arange(n_out)] = 1.0
    e_from_z = sel_in @ c[:n_adc]
    dk = np.asarray(controller.d, dtype=float)
    ck = np.asarray(controller.c, dtype=float)
    # u_fb = ck x + dk (E z - r); z+ = a z + b (S u_fb + w); x+ = ak x + bk (E z - r).
    big_a = np.zeros((nz + nk, nz + nk))
    big_a[:nz, :nz] = a + b @ sel_out @ dk @ e_from_z
    big_a[:nz, nz:] = b @ sel_out @ ck
    big_a[nz:, :nz] = controller.b @ e_from_z
    big_a[nz:, nz:] = controller.a
    m = b.shape[1]
    big_b = np.zeros((nz + nk, m + n_in))
    big_b[:nz, :m] = b
    big_b[:nz, m:] = -(b @ sel_out @ dk)
    big_b[nz:, m:] = -np.asarray(controller.b, dtype=float)
    # The controller's commands: ck x + dk E z - dk r. The -dk r term is a feedthrough from the
    # reference, kept out of the state-space outputs (reference_feedthrough gives it); the DAC
    # excitations have none.
    fb = np.hstack([dk @ e_from_z, ck])
    big_c = np.vstack([np.hstack([c, np.zeros((c.shape[0], nk))]), fb])
    names_in = tuple(plant.input_names) + tuple(
        reference_name(ADC_CHANNELS[i] if n_adc == len(ADC_CHANNELS) else f"adc{i}")
        for i in controller.adc_inputs)
    names_out = tuple(plant.output_names) + tuple(
        feedback_name(DAC_CHANNELS[j] if m == len(DAC_CHANNELS) else f"dac{j}")
        for j in controller.dac_outputs)
    return DiscretePlant(a=big_a, b=big_b, c=big_c, ts_s=plant.ts_s, input_names=names_in,
                         output_names=names_out, n_plant_states=nz + nk,
                         input_delay_samples=tuple(plant.input_delay_samples) + (0.0,) * n_in)
