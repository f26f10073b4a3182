"""The ``interfaces`` subcommand: build a user's interface packages (composed_sim.interfaces)."""
from __future__ import annotations

from composed_sim.command_line import UserError


def cmd_interfaces(args) -> int:
    from composed_sim.interfaces import InterfaceError, build_package
    built = []
    for folder in args.packages:
        try:
            package = build_package(folder, after=built)
        except InterfaceError as e:
            raise UserError(str(e)) from None
        built.append(package)
        how = f"cached, found in {package.seconds:.2f} s" if package.cached else f"built in {package.seconds:.1f} s"
        print(f"{package.name}: {how}: {package.prefix}")
    paths = ":".join(str(p.python_path) for p in built)
    print(f"import its messages with PYTHONPATH={paths} (a world file's `interfaces:` does this itself)")
    return 0
