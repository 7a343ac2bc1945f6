"""Reports on a compiled model: the check and equation dumps (report, latex), draw (Graphviz), plot
(matplotlib figures).  Entry: report.check_report (`bgc check`); report.equations_text and
equations_latex (`bgc equations`), draw.draw_dot (`bgc draw`), plot.plot_run (`--plot`)."""
