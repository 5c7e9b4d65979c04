"""What each sensor writes into the canonical record (pipeline.core.record, docs/dataset.md): its files, its
label rows and its entry in record.json. One module per sensor kind; a new sensor adds one.

The writers take the renderer's outputs as they are (a camera frame with ``rgb``, ``instance_id``, ``semantic``,
``depth_m``, ``depth_valid`` and ``labels``; a LiDAR sweep; a sensor with ``config``, ``mount`` and, for cameras,
``K``) without importing the renderer: the record is the lowest layer, which every other one may read.
"""
