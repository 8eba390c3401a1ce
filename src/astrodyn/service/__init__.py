"""The service layer (docs/architecture.md, sections 1 and 3): the processes of a run and
their supervisors.  Each process is a ``main()`` in a module here, started with
``python -m astrodyn.service.<name>``: ``logger``, ``propagator``, ``replay``, ``router``;
``runner`` (``astrodyn run``) and ``serve`` (``astrodyn serve``) supervise them through
``children``."""
