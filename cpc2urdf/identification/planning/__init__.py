"""Planning a stage-1 experiment before measuring it.

Which configurations should be measured, how many, and how good will the result be? Given a
robot, a measuring setup (stereo rig, the robot's place in front of it, the noise: Fig. 10 pose
noise, stereo pixel noise with a covariance per view (:mod:`stereo`), or marker points
(:mod:`markers`)) and a list
of configurations, :mod:`prediction` gives the Cramér-Rao covariance of the identified parameters
at the nominal model and the held-out position/orientation error it implies over the user's task
region, and names the parameters the plan leaves undetermined. :mod:`optimal` chooses N
configurations from a candidate set that minimise that predicted error (I-optimal) or maximise the
information determinant (D-optimal), by greedy selection then Fedorov exchange; :mod:`plan` ties
it together (candidates the rig can see, the curve of predicted error vs N per strategy, the
smallest N for a requested accuracy); :mod:`plan_file` is the ``cpc2urdf/plan@1`` file;
:mod:`experiment` simulates measuring a plan (the validation of the prediction).

Layer: above ``simulation`` (it uses the rig's visibility and the robot's placement) and
``kinematics`` (the identification problem's Jacobian); docs/planning.md.
"""
