"""Preloaded, first, by the fork server of a sweep's local Dask cluster (bgc.execute.sweeps): SIGINT
ignored there, and so in every worker it forks (a fork server hands its children the
handlers it had once its preloads were imported), when bgc asks for it by IGNORE_SIGINT in
the fork server's environment.  Imported anywhere else, it does nothing."""
import os
import signal

IGNORE_SIGINT = "BGC_WORKERS_IGNORE_SIGINT"

if os.environ.pop(IGNORE_SIGINT, None) == "1":
    signal.signal(signal.SIGINT, signal.SIG_IGN)
