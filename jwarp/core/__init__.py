"""Layer 2 of jwarp: the one input front door (:mod:`.arrays`), the device model
(:mod:`.device`: ``put_model -> DeviceModel`` and the workspaces), typed DH rows
(:mod:`.rows`) and joint-limit tables (:mod:`.limits`). Imports only the model and the
kernels."""
