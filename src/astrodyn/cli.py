"""The ``astrodyn`` command.

Each sub-command lives in its own module and exposes ``main(argv) -> int``; this
file only dispatches, so ``astrodyn --help`` stays fast (nothing heavy is imported
until a sub-command runs).
"""

from __future__ import annotations

import importlib
import sys

from astrodyn.console import keep_working_when_output_closes

# sub-command -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("astrodyn.demo", "run the demo scene (the README's main job)"),
    "bench": ("astrodyn.bench", "speed-against-error benchmarks: orbit | attitude | service | sweep | encode | auth | calls | view | control | flexible | soak | all"),
    "run": ("astrodyn.service.runner", "run a scenario headless into an MCAP file"),
    "serve": ("astrodyn.service.serve", "long-running real-time service controlled over Zenoh"),
    "replay": ("astrodyn.service.replay", "republish a recorded MCAP on Zenoh"),
    "analyze": ("astrodyn.analysis", "report and plots from an MCAP file (or a sweep directory)"),
    "export": ("astrodyn.recording.export", "export an MCAP to csv | parquet | oem | aem | foxglove"),
    "recover": ("astrodyn.recording.recover", "rewrite a crashed writer's MCAP with a summary"),
    "merge": ("astrodyn.recording.merge", "merge partial recordings of one run into one file, without duplicates"),
    "validate": ("astrodyn.scenario", "check a scenario config and print what it would run"),
    "sweep": ("astrodyn.sweep", "Monte Carlo dispersions / parameter sweeps of a scenario on Dask"),
    "router": ("astrodyn.service.router", "a Zenoh router so processes on several hosts meet"),
}


def _usage() -> str:
    width = max(len(c) for c in COMMANDS)
    lines = ["usage: astrodyn COMMAND [ARGS...]", "", "commands:"]
    lines += [f"  {name:<{width}}  {help_}" for name, (_, help_) in COMMANDS.items()]
    lines += ["", "`astrodyn COMMAND --help` for the options of one command."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    keep_working_when_output_closes()  # a closed pipe on stdout / stderr never ends a run (astrodyn.console)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0
    if argv[0] in ("-V", "--version"):
        from astrodyn import __version__

        print(f"astrodyn {__version__}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"astrodyn: unknown command {name!r}; expected one of: {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(COMMANDS[name][0])
        return int(module.main(rest) or 0)
    except KeyboardInterrupt:  # Ctrl-C before a command set up its own handling (or one that has none)
        print(f"astrodyn {name}: interrupted by SIGINT", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
