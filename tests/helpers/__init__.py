"""Shared test helpers (imported by test modules as ``helpers.<module>``; tests never import
each other):

* ``blender``: the add-on registered from the checkout, images' pixels, relit colours as a
  render shows them, a point light, a grey box, Relight's state.
* ``room``: the suite's small test room (``build_scene``).
* ``office``: the demo office photographed and its Cycles truth (virtual lamps and objects).
* ``formfactors``: independent form-factor references (Howell's closed forms, pyviewfactor,
  brute-force integration) and deterministic patch-pair generators.
"""
