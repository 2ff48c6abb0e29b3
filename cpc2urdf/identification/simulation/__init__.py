"""Simulated experiments: a "true" robot measured by a simulated rig (docs/measurements.md, sec. 4).

Modules (import each by its full name; this package re-exports nothing, so that importing the
noise models does not load the placement search and the renderer):

- ``design``: the experiment design: the one calibration-range rule (``calibration_ranges``),
  the one-joint-at-a-time protocol of sec. 4.1 (``protocol_configurations``, ``protocol_q``),
  random configurations, the measured frames.
- ``truth``: the true robot, the nominal one with seeded geometric errors (``perturbed_model``).
- ``noise``: measurement noise models: Fig. 10 (``fig10_noise``, the one pose-perturbation
  convention) and a stereo rig's pixel noise (``stereo_noise``).
- ``measure``: a robot's plate poses under a noise model (``measure_poses``).
- ``visibility``: the view check (``check_view``) and held-out configurations the rig can see.
- ``placement``: the robot's placement in front of the rig (``clear_placement``, cached).
- ``simulate``: the whole stage-1 experiment (``simulate_experiment``).
- ``images``: whole experiments rendered as the image folders ``cpc2urdf measure`` reads.
- ``random_robots``: seeded random trees with plates, for tests and studies (``random_model``).
"""
