"""Hand-eye calibration: put the head's cameras into the model (Shih et al. sec. 5).

Modules (hand-eye imports the core package, vision and kinematics):

- :mod:`~cpc2urdf.identification.handeye.axxb`: conventions, input checks, diagnosis and the
  result type every solver shares; the ``A X = X B`` solvers (Tsai-Lenz, Park-Martin, Daniilidis);
- :mod:`~cpc2urdf.identification.handeye.axzb`: the ``A X = Z B`` solvers (Li et al. 2010:
  Kronecker, dual quaternions, Zhuang; joint refinement);
- :mod:`~cpc2urdf.identification.handeye.solvers`: the one registry of every solver and
  ``calibrate(T_base_hand, T_camera_target, method)``;
- :mod:`~cpc2urdf.identification.handeye.gate.handeye_gate`: the consistency gate (do the poses agree
  with ``A X = Z B`` and their noise? which mistake explains them?), with its report
  (:mod:`~cpc2urdf.identification.handeye.gate.gate_report`), the mistakes it tests
  (:mod:`~cpc2urdf.identification.handeye.gate.mistakes`), the noise model
  (:mod:`~cpc2urdf.identification.handeye.pose_noise`) and its own fits
  (:mod:`~cpc2urdf.identification.handeye.gate.reference_fit`);
- :mod:`~cpc2urdf.identification.handeye.pose_file`: the ``cpc2urdf/handeye-poses@1`` file;
- :mod:`~cpc2urdf.identification.handeye.stage2`: the stage-2 pipeline (simulated cameras,
  solvePnP, hand-eye, camera frames into the model);
- :mod:`~cpc2urdf.identification.handeye.head_images`: measured head-camera target poses + the
  identified model -> pose files or stage-2 observations.
"""
