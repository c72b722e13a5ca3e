"""Scenes: the validated, immutable description of a chain, and where it comes from.

- :mod:`.records`: the records (`Scene`, `Body`, `Joint`, `Rotor`, ...) everything downstream reads
- :mod:`.load`: `load_scene` (a YAML file, a shipped scene's name, or a mapping), every error
  naming its key path
- :mod:`.urdf`: the chain's shapes for drawing, and its URDF on /robot_description
"""
