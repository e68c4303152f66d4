"""What every SUMO domain shares: :mod:`~ials_zoo.sumo.lease` (libsumo's one simulation per
process, worker processes) and :mod:`~ials_zoo.sumo.command` (the SUMO command line).

Not a domain: no ``domain.py`` here, and nothing here names one.
"""
