"""Studies: which effects can a protocol detect, and from what size? Many twin scenarios
(a spec, `spec`, expanded into `cells`) simulated and diagnosed (`cell`) on Dask
distributed (`engine`), each row stored as it finishes (`store`), summarised in a report
(`report`)."""
