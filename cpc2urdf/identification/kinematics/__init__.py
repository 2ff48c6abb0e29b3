"""Kinematic identification: CPC parameters from measured frame poses and joint readings.

Modules (import each by its full name; this package re-exports nothing, so that importing one
does not load scipy's optimiser for every command):

- ``protocol``: recognise the one-joint-at-a-time protocol (``q0``, each joint's sweep).
- ``closed_form``: Shih et al. sec. 4.2 generalised to trees (``identify_closed_form``).
- ``parametrization``: the minimal local chart of a model's identifiable parameters.
- ``problem``: the maximum-likelihood problem, weighted residuals of eq. (23) and their Jacobian
  (``IdentificationProblem``).
- ``refine``: the weighted least-squares refinement and its robust mode (``refine``).
- ``identifiability``: rank analysis of the weighted Jacobian, named free combinations.
- ``uncertainty``: parameter covariance, its propagation to frame positions, the Cramér-Rao bound.
- ``start``: where a refinement starts (the closed form, or the nominal model placed in world).
- ``methods``: identification methods by name (``identify``, ``METHODS``), including the CLI's
  default "closed form, then refine" (``identify_refined``); ``identify`` runs the checks below.
- ``sufficiency``: records that cannot determine the robot, refused before any solver runs.
- ``fit_statistics``: the fit's residuals against the stated noise (chi-square, both tails).
- ``plausibility``: the size of the robot the data imply, against the nominal model or the limits.
- ``alternatives``: the likely mistakes in a measurement file, each as the fix that undoes it.
- ``verdict``, ``diagnosis``, ``consistency``: the consistency gate after every fit (its tests and
  report, the refits that name the cause, and ``check_consistency``).
"""
