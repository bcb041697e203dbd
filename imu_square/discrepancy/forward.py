"""The simulator, run at a recording's analysed samples: the forward model.

For each analysed (or transient) sample at recording time ``t`` in block ``b`` of run ``r``,
the simulator is evaluated at its true time

    tau = T_b + anchor_b + (t - t_mid_b) / (1 + ppm 1e-6)

where ``T_b`` is when the tool is at the middle of block ``b``'s arc on the
simulator's timeline (3 s lead-in, as ``imu-square simulate`` lays it; the
middle of its motion when the feed ramps mirror each other, as our own
trajectory's do; a controller's motion, when given, need not),
``t_mid_b`` the motion midpoint the pipeline detected in the recording, and
``ppm`` the sensor's clock error (the recording's clock runs ``ppm`` fast,
as in :func:`imu_square.simulate.simulate_run`).

The anchors are free, but the detection says how the blocks sit relative to
one another to within its uncertainty ``u_b``: a prior ``(anchor_b - c) /
u_b``, ``c`` their weighted mean, joins the fit vector. On a plain circle it
is what tells the sensor's rotation from a time shift (as the pipeline's
anchoring does); where the recording has sharp features (a friction spike
starts with a step in acceleration) they place each block to the sample. The reading is the
simulator's own chain (:mod:`imu_square.simulate.signal`) with its analytic
derivatives of the motion. Each stage of the chain is kept for the last few
models asked, so a finite difference by a sensor parameter reruns only the
sensing, one by an axis's drive parameter only that axis and what follows.
"""

from collections import OrderedDict
from dataclasses import replace

import numpy as np

from imu_square.simulate.signal import axis_motion, axis_parameters, model_timeline, sense_motion

LEAD_IN_S = 3.0
LEAD_OUT_S = 3.0


class ForwardModel:
    """The model's x and y readings at a layout's analysed samples.

    Parameters
    ----------
    layout : Layout
        The analysed samples.
    operator : FeatureOperator
        Their features.
    motion : SampledMotion, optional
        The commanded motion, a controller's; our own trajectory of the
        layout's program (with the machine's feed ramps) if None.
    """

    def __init__(self, layout, operator, motion=None):
        self.layout = layout
        self.operator = operator
        self.motion = None if motion is None else motion.placed(LEAD_IN_S, LEAD_OUT_S)
        self._timelines = {}
        self._t_mid = np.array([b.t_mid_s for b in layout.blocks])
        self._index = np.array([b.index for b in layout.blocks])
        # the simulator takes increasing times; the transient samples follow the analysed ones
        self._order = np.argsort(layout.t_s, kind="stable")
        self.n_blocks = len(layout.blocks)
        u = np.array([b.u_t_mid_s for b in layout.blocks])
        self._prior_w = 1.0 / u**2
        self.evaluations = 0
        self._stages = {}

    def _stage(self, name, key, compute, keep=4):
        """The result of ``compute()`` for ``key``, kept for the last ``keep`` keys."""
        store = self._stages.setdefault(name, OrderedDict())
        if key in store:
            store.move_to_end(key)
            return store[key]
        value = compute()
        store[key] = value
        if len(store) > keep:
            store.popitem(last=False)
        return value

    def timeline(self, machine):
        """The simulator's timeline of the program for this machine's feed ramps, or the motion."""
        if self.motion is not None:
            return self.motion
        key = (machine.ramp_s, machine.ramp_profile)
        if key not in self._timelines:
            self._timelines[key] = model_timeline(self.layout.program, machine, LEAD_IN_S)
        return self._timelines[key]

    def _times(self, state, t_s, blocks):
        """Simulator time of recording times ``t_s`` in layout blocks ``blocks``. [s]"""
        tl = self.timeline(state.machine)
        mids = np.array(
            [tl.blocks[i].time_at_progress(0.5 * tl.blocks[i].angle_rad) for i in self._index]
        )
        anchors = np.asarray(state.anchors_s, dtype=float)
        scale = 1.0 + state.sensor.clock_ppm * 1e-6
        return mids[blocks] + anchors[blocks] + (t_s - self._t_mid[blocks]) / scale

    def true_times(self, state):
        """Simulator time of each analysed (or transient) sample. [s]"""
        return self._times(state, self.layout.t_s, self.layout.sample_block)

    def samples_at(self, state, t_s, block):
        """Noise-free x and y at any recording times of one block (nothing kept).

        Parameters
        ----------
        state : ModelState
            The model.
        t_s : ndarray
            Recording times, increasing. [s]
        block : int
            Position of their block in the layout.

        Returns
        -------
        ndarray, shape (len(t_s), 2)
            [m/s^2]
        """
        m = state.machine
        tau = self._times(state, np.asarray(t_s, dtype=float), np.full(len(t_s), block))
        timeline = self.timeline(m)
        paths = [axis_motion(timeline, m, tau, a) for a in (0, 1)]
        pos, _, acc = m.geometry.apply(paths[0], paths[1], tau)
        return sense_motion(m, state.sensor, pos, acc, tau)[:, :2]

    def samples(self, state):
        """Noise-free x and y at the analysed samples.

        Parameters
        ----------
        state : ModelState
            The model.

        Returns
        -------
        ndarray, shape (m, 2)
            [m/s^2]
        """
        self.evaluations += 1
        m, s = state.machine, state.sensor
        timeline = self.timeline(m)
        when = (tuple(state.anchors_s), s.clock_ppm, m.ramp_s, m.ramp_profile)
        tau = self._stage("time", when, lambda: self.true_times(state)[self._order])
        keys = [(when, axis_parameters(m, a)) for a in (0, 1)]
        paths = [
            self._stage(f"axis{a}", keys[a], lambda a=a: axis_motion(timeline, m, tau, a))
            for a in (0, 1)
        ]
        pos, _, acc = self._stage(
            "geometry", (*keys, m.geometry), lambda: m.geometry.apply(paths[0], paths[1], tau)
        )
        out = np.empty((tau.size, 2))
        out[self._order] = sense_motion(m, s, pos, acc, tau)[:, :2]
        return out

    def prior(self, state):
        """The whitened prior on the anchors: ``(anchor_b - c) / u_b``."""
        a = np.asarray(state.anchors_s, dtype=float)
        c = np.sum(a * self._prior_w) / np.sum(self._prior_w)
        return (a - c) * np.sqrt(self._prior_w)

    def features(self, state):
        """Features of the model's readings (:class:`Features`), with the anchors' prior."""
        f = self.operator.transform(self.samples(state))
        return replace(f, prior=self.prior(state))
