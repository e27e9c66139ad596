"""Where ``layersim mc`` runs its walks: ``--workers N`` (a local Dask cluster), ``--cluster
ADDRESS`` (a running Dask scheduler, with ``--tls-ca-file``, ``--tls-cert``, ``--tls-key``) or
``--devices all|cuda:0,cuda:1`` (one thread per device of this host); none of them: this process.

:func:`check_options` checks the options (one line naming the option) before any scene is read
or any cluster starts; :func:`make_executor` then starts what they ask for and resolves the
backend where the walks will run (on the cluster's workers for ``--cluster``). The Monte Carlo
modules are imported only then, so that building the parser stays light.
"""

from __future__ import annotations

__all__ = ["add_options", "check_options", "make_executor"]


def add_options(sp) -> None:
    """The options of ``layersim mc`` that say where the walks run."""
    g = sp.add_argument_group("where the walks run (default: this process)")
    g.add_argument("--workers", type=int, metavar="N",
                   help="a local Dask cluster of N single-threaded worker processes")
    g.add_argument("--cluster", metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:8786, tls://...); its workers "
                        "need this layersim installed and run pickled tasks: trust it")
    g.add_argument("--tls-ca-file", metavar="PEM", help="CA certificate of a TLS cluster")
    g.add_argument("--tls-cert", metavar="PEM", help="this client's certificate (TLS cluster)")
    g.add_argument("--tls-key", metavar="PEM", help="its private key, if not in --tls-cert")
    g.add_argument("--devices", metavar="all|LIST",
                   help="one thread per device of this host: 'all' (every device of the "
                        "backend) or e.g. cuda:0,cuda:1")


def check_options(args) -> None:
    """Refuse contradictory or malformed options (one line naming the option).

    Raises
    ------
    ValueError
    """
    from .montecarlo.executors import tls_security
    from .montecarlo.executors.devices import parse_devices
    chosen = [o for o, v in (("--workers", args.workers), ("--cluster", args.cluster),
                             ("--devices", args.devices)) if v is not None]
    if len(chosen) > 1:
        raise ValueError(f"{chosen[0]} and {chosen[1]} exclude each other: choose where the "
                         "walks run")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    tls = {"--tls-ca-file": args.tls_ca_file, "--tls-cert": args.tls_cert,
           "--tls-key": args.tls_key}
    given = [o for o, v in tls.items() if v is not None]
    if given and args.cluster is None:
        raise ValueError(f"{given[0]} applies to --cluster only")
    if args.cluster is not None and not args.cluster.strip():
        raise ValueError("--cluster needs a scheduler address such as tcp://host:8786")
    if args.devices is not None:
        parse_devices(args.devices)
    try:
        tls_security(args.tls_ca_file, args.tls_cert, args.tls_key)
    except ValueError as exc:            # "tls_cert: ..." -> "--tls-cert: ..."
        field, _, rest = str(exc).partition(":")
        raise ValueError(f"--{field.replace('_', '-')}:{rest}") from None


def make_executor(args, backend: str, resolve_here):
    """Start what the options ask for and resolve ``backend`` where the walks run.

    Parameters
    ----------
    args : argparse.Namespace
        Checked by :func:`check_options`.
    backend : str
        The backend asked for (``"auto"`` or a name).
    resolve_here : callable
        Resolves and checks a backend name on this machine (``--backend``'s check).

    Returns
    -------
    executor : object or None
        An executor (:mod:`layersim.montecarlo.executors`), or None for this process.
    backend : str
        The resolved backend.
    """
    from .montecarlo.backends import BACKENDS
    from .montecarlo.executors import Dask, Devices, tls_security
    from .montecarlo.executors.devices import parse_devices
    if args.cluster is not None:
        if backend not in BACKENDS:
            raise ValueError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        ex = Dask(address=args.cluster,
                  security=tls_security(args.tls_ca_file, args.tls_cert, args.tls_key))
        try:
            return ex, ex.resolve_backend(backend)
        except BaseException:
            ex.close()
            raise
    backend = resolve_here(backend)
    if args.workers is not None:
        return Dask(workers=args.workers), backend
    if args.devices is not None:
        return Devices(backend, parse_devices(args.devices)), backend
    return None, backend
