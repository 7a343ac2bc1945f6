"""Reports on a compiled model: the check and equation dumps (report, latex), draw (Graphviz), plot
(matplotlib figures)."""
