"""Views of gyro_sim runs in rerun (rerun-sdk is imported only inside these modules).

- :mod:`.translate`: messages (from a log or from DDS) to rerun entities and plots, one
  translator for both views.
- :mod:`.chain`: the chain's shapes from a scene or a URDF.
- :mod:`.rerun_view`: ``gyro-sim view LOG``, its layout and headless screenshots.
- :mod:`.live`: ``gyro-sim view --live``, a running node followed over DDS.
- :mod:`.commands`: the ``view`` command's options.
- :mod:`.measure_live`: the live view's lag and what it costs the node.
"""
