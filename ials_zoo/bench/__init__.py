"""``ials-zoo bench``'s measurements, apart from its command line: :mod:`~ials_zoo.bench.timings`
(seconds per unit of one simulator or learner), :mod:`~ials_zoo.bench.measure` (the repeated,
interleaved measurements of a domain) and :mod:`~ials_zoo.bench.report` (the figures in words
and plots). A domain's own part of the bench (a GS-only domain's networks, the sizes it grows
to) lives with the domain and is reached through :func:`ials_zoo.core.extras.bench_of`."""
