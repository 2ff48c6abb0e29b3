"""Vision and measurement: calibration images to poses (Shih et al. secs. 3 and 5).

Modules, lowest first (vision imports only the core package):

- :mod:`~cpc2urdf.identification.vision.targets`: the calibration targets (``PlateDesign``; the
  stage-1 plates, the stage-2 25-disk target and its ``TARGET_*`` constants);
- :mod:`~cpc2urdf.identification.vision.stereo`: the calibrated stereo rig (projection,
  triangulation); :mod:`~cpc2urdf.identification.vision.rig_file`: its file (and camera files);
- :mod:`~cpc2urdf.identification.vision.render`: synthetic images of the targets;
- :mod:`~cpc2urdf.identification.vision.detect`: images to identified circle centres;
- :mod:`~cpc2urdf.identification.vision.plate_poses`: circle centres to poses (stereo
  triangulation + registration, PnP, ellipse-centre bias);
- :mod:`~cpc2urdf.identification.vision.joints_csv`, :mod:`~cpc2urdf.identification.vision.image_folders`:
  the joint readings and the images of a measurement folder, and the ``on_error`` policy;
- :mod:`~cpc2urdf.identification.vision.measure_stereo`: stage 1, stereo images -> measurement set;
- :mod:`~cpc2urdf.identification.vision.measure_head`: stage 2, head-camera images -> target poses.

Hand-eye input from these target poses is :mod:`cpc2urdf.identification.handeye.head_images`;
rendering whole experiments is :mod:`cpc2urdf.identification.simulation.image_experiment`.
"""
