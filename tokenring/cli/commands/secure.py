"""``tokenring secure``: set up a secured deployment (the library is :mod:`tokenring.host.secure`)."""

from __future__ import annotations

import argparse

HELP = "TLS certificates and access rules for a ring only its operator controls"

EXAMPLES = """\
examples:
  tokenring secure init ./ring-keys --host 10.0.0.5 --host robot.lan
  # on the ring's host (every ring process gets the same file):
  tokenring up --listen tls/10.0.0.5:7447 --zenoh-config ring-keys/node.json5
  # on the operator's PC: download programs, inject faults, stop
  tokenring load -e tls/10.0.0.5:7447 --zenoh-config ring-keys/operator.json5
  # anyone else may only watch
  tokenring sniff -e tls/10.0.0.5:7447 --zenoh-config ring-keys/observer.json5
"""


def host(text: str) -> str:
    """An argparse type: an IP address or host name a certificate can name."""
    from tokenring.errors import UsageError
    from tokenring.host.secure import check_host

    try:
        return check_host(text)
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--host ")) from None


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_json_option, positive_int, with_examples

    p = sub.add_parser(
        "secure",
        help=HELP,
        description=(
            "Create a deployment's own certificate authority and one Zenoh config per role: "
            "node (the ring's processes), operator (may download programs, inject faults, stop "
            "the ring) and observer (may only read). Peers without a certificate of this "
            "authority cannot connect at all."
        ),
        **with_examples(EXAMPLES),
    )
    verbs = p.add_subparsers(dest="secure_verb", metavar="VERB", required=True)
    init = verbs.add_parser(
        "init",
        help="write ca.pem, ca-key.pem and node/operator/observer.json5 into DIR",
        **with_examples(EXAMPLES),
    )
    init.add_argument("directory", metavar="DIR", help="where to write (created if missing)")
    init.add_argument(
        "--host",
        action="append",
        type=host,
        metavar="HOST",
        help="an address the ring listens on (IP or name; repeat for each host; "
        "default: localhost and 127.0.0.1)",
    )
    init.add_argument("--days", type=positive_int, default=365, help="validity (default %(default)s)")
    init.add_argument("--force", action="store_true", help="replace an existing deployment in DIR")
    add_json_option(init)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tokenring.cli.output import print_json
    from tokenring.host.secure import DEFAULT_HOSTS, create_deployment

    deployment = create_deployment(
        Path(args.directory), tuple(args.host or DEFAULT_HOSTS), days=args.days, force=args.force
    )
    if args.json:
        print_json(
            {
                "directory": str(deployment.directory),
                "files": {name: str(path) for name, path in deployment.files.items()},
                "hosts": list(deployment.hosts),
                "not_after": deployment.not_after.isoformat(timespec="seconds"),
            }
        )
        return 0
    files = deployment.files
    print(f"a secured deployment in {deployment.directory} (valid until {deployment.not_after:%Y-%m-%d}):")
    print(f"  {files['node']}      the ring's processes, on every host of the ring")
    print(f"  {files['operator']}  the operator's PC: download, faults, stop")
    print(f"  {files['observer']}  observers: read only")
    print(f"  {files['ca-key']}    the authority's key: keep it off the ring's hosts")
    host = deployment.hosts[-1]
    print(f"listen on one of {', '.join(deployment.hosts)}, e.g.:")
    print(f"  tokenring up --listen tls/{host}:7447 --zenoh-config {files['node']}")
    print(f"  tokenring status -e tls/{host}:7447 --zenoh-config {files['observer']}")
    return 0
