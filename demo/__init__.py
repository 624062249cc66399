"""`make demo`: the Cornell box solve (demo.cornell) and the relit office (demo.office)."""
