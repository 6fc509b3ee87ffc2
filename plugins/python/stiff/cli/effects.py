"""stiff effects: the physical effects the model can contain."""
from __future__ import annotations

import json
import textwrap

from .. import api
from ..errors import StiffError
from .common import Formatter, robot_path

EXAMPLE = """example:
  stiff effects                      # every effect with a one-line explanation
  stiff effects backlash --robot rokae   # its parameters, units and reference
Use the names in --model, joined by '+': stiff identify --model joint+backlash ..."""


def register(sub):
    p = sub.add_parser("effects", help="list the physical effects and their parameters",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    p.add_argument("name", nargs="?", help="show one effect in detail")
    p.add_argument("--robot", "-r", help="robot (parameter lists depend on its joints)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def run(args):
    robot = api.Robot(robot_path(args.robot)) if args.robot else None

    def listed(name):
        """One effect this robot cannot carry (no link masses) must not hide the others."""
        try:
            return api.describe_effect(name, robot)
        except StiffError as e:
            info = api.describe_effect(name)
            info["unavailable"] = str(e).split(": ", 1)[-1]
            return info

    infos = [api.describe_effect(args.name, robot)] if args.name else [
        listed(n) for n in api.effects()]
    if args.json:
        print(json.dumps(infos if not args.name else infos[0], indent=2))
        return 0
    for info in infos:
        needs = f"  (needs: {', '.join(info['needs'])})" if info["needs"] else ""
        print(f"{info['name']:<20} {info['description']}{needs}")
        if "unavailable" in info:
            print(f"{'':<20} not available for this robot: {info['unavailable']}")
            continue
        if args.name:
            print(textwrap.fill(f"reference: {info['reference']}", 100, subsequent_indent="  "))
            print("parameters:")
            for p in info["parameters"]:
                print(f"  {p['name']:<12} [{p['unit']}]  {p['meaning']}")
        else:
            units = sorted({p["unit"] for p in info["parameters"]})
            n = len(info["parameters"])
            print(f"{'':<20} {n} parameter{'s' if n != 1 else ''} [{', '.join(units)}]")
    return 0
