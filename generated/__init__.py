"""Generated code, committed (never edited by hand): the element kernels and the runtime
(``kernels/``, ``runtime/``), and the whole-scene models of the bundled scenes
(``<scene>_<formulation>/``).  Installed as the data package ``flexbody_generated`` so a
non-editable install carries it and nothing bundled is derived on a user's machine.
"""
