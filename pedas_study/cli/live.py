"""`pedas-study live serve | drive`: live pEDAS advice for a lab's simulator, and the reference client that drives a
virtual participant in SUMO through the socket."""
from __future__ import annotations

import sys

from pedas_study.cli.common import db_path, open_store
from study.common.errors import UserError


def _serve(args) -> None:
    from pedas.live import LiveRoute, LiveServer

    from study.store.store import StoreHolder

    from pedas.hud_theme import check_theme

    try:
        check_theme(args.theme)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    for flag, value in (("--udp-idle", args.udp_idle), ("--max-rate", args.max_rate),
                        ("--max-sessions", args.max_sessions)):
        if not value > 0:   # also refuses nan
            raise UserError(f"{flag} must be a positive number, got {value:g}")
    if not 0 <= args.port <= 65535:
        raise UserError(f"--port must be 1-65535 (or 0: any free port), got {args.port}")

    st = None
    if not args.no_log:
        # a missing store fails before the route is loaded; then the store is open only while a drive log writes
        # (about once a second), so CLI commands can use it during a session (docs/store.md)
        with open_store(args) as checked:
            st = StoreHolder(checked.path, checked.actor)
    try:
        live = LiveRoute.load(args.route)

        def drive_log(participant: str, condition: str):
            from study.logs.live_log import LiveDriveLog

            return LiveDriveLog(st, participant, condition, route=live.name, replace=args.replace)

        def ready(port: int) -> None:
            where = "no drive log" if st is None else f"drive logs into {db_path(args)}"
            print(f"listening on ws://{args.host}:{port}/ and udp://{args.host}:{port} (route {live.name}, {where}); "
                  f"HUD page http://{args.host}:{port}/?pair=CODE with the code each session prints", flush=True)

        def announce(line: str) -> None:   # a session's pairing code and HUD page, a UDP session's end
            print(line, flush=True)

        server = LiveServer(live, args.host, args.port, logger_factory=None if st is None else drive_log,
                            on_ready=ready, announce=announce, rate=args.max_rate,
                            burst=max(1, round(args.max_rate / 2)), udp_idle=args.udp_idle,
                            max_sessions=args.max_sessions)
        server.hud_theme, server.tone_rule = args.theme, args.tone
        server.visual_warning = args.visual_warning == "on"
        try:
            server.run()
        except OSError as exc:   # address in use, no such interface: the operator's input
            raise UserError(f"cannot listen on {args.host}:{args.port}: {exc.strerror or exc}") from None
    finally:
        if st is not None:
            st.shut()


def _drive(args) -> None:
    import time

    import numpy as np

    from pedas.drive import drive
    from pedas.live_client import RemoteController

    from pedas.live_client import LiveError

    t0 = time.perf_counter()
    try:
        with RemoteController(args.url, participant=args.participant, condition="pedas") as ctrl:
            df = drive(args.seed, args.style, "pedas", traffic_seed=args.traffic_seed, controller=ctrl)
    except (OSError, LiveError) as exc:   # no server there, or it refused the session
        raise UserError(f"live server {args.url}: {exc}") from None
    lat = np.asarray(ctrl.latencies) * 1e3
    print(f"drove {len(df)} samples ({df['t'].iloc[-1]:.1f} s simulated) through {args.url} in "
          f"{time.perf_counter() - t0:.1f} s; round trip median {np.median(lat):.2f} ms, "
          f"p99 {np.percentile(lat, 99):.2f} ms; logged as drive {ctrl.done['drive_id']}")
    if args.compare:
        # the socket's drive log has no HUD channels (the server logs what it showed): compare the drive logs
        ref = drive(args.seed, args.style, "pedas", traffic_seed=args.traffic_seed, hud_channels=False)
        same = ref.equals(df)
        print(f"in-process drive with the same seeds: {'identical' if same else 'DIFFERENT'} log "
              f"({len(ref)} samples)")
        if not same:
            sys.exit(1)


def register(cli) -> None:
    """Declare the `live` group."""
    from pedas.live_limits import MAX_SESSIONS, RATE, UDP_IDLE
    from pedas.vocabulary import STYLES

    g = cli.group("live", "live pEDAS advice for a driving simulator (WebSocket/UDP, docs/hud.md)")
    p = g.command("serve", "run the controller behind the live protocol; log participants' drives into the store",
                  _serve)
    p.add_argument("--route", default="study", choices=("study", "synthetic-mixed"), help="route (default study)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8765, help="WebSocket/HTTP and UDP port (default 8765; 0 = any)")
    p.add_argument("--no-log", action="store_true", help="log no drives (no store needed)")
    p.add_argument("--replace", action="store_true", help="a session may replace a stored drive")
    p.add_argument("--max-rate", dest="max_rate", type=float, default=RATE, metavar="HZ",
                   help=f"messages/s one client may send; faster ones are slowed (UDP: dropped) (default {RATE:g})")
    p.add_argument("--theme", default="light", metavar="NAME",
                   help="HUD page theme: light (opaque panel, default) or dark (black = see-through, projected HUD)")
    p.add_argument("--tone", default="unfollowed", choices=("unfollowed", "margin"),
                   help="when the HUD sounds: unfollowed (a slow-down advice not followed for 2 s, default) or margin "
                        "(that, and the safe distance violated; docs/hud.md)")
    p.add_argument("--visual-warning", dest="visual_warning", choices=("on", "off"), default="on",
                   help="the warning triangle and blinking border beside the tone (default on)")
    p.add_argument("--udp-idle", dest="udp_idle", type=float, default=UDP_IDLE, metavar="S",
                   help=f"seconds without a datagram after which a UDP session ends (default {UDP_IDLE:g})")
    p.add_argument("--max-sessions", dest="max_sessions", type=int, default=MAX_SESSIONS, metavar="N",
                   help=f"simulator sessions at once over WebSocket, and over UDP; more are refused "
                        f"(default {MAX_SESSIONS})")
    p = g.command("drive", "reference client: a virtual participant drives in SUMO with advice from a live server",
                  _drive)
    p.add_argument("--url", default="ws://127.0.0.1:8765/", help="the server (default ws://127.0.0.1:8765/)")
    p.add_argument("--seed", type=int, default=0, help="the virtual person's seed (default 0)")
    p.add_argument("--style", default="normal", choices=STYLES, help="driving style (default normal)")
    p.add_argument("--traffic-seed", dest="traffic_seed", type=int, default=None,
                   help="traffic seed (default: the person's seed)")
    p.add_argument("--participant", default=None, metavar="ID", help="log the drive as this participant's pedas drive")
    p.add_argument("--compare", action="store_true",
                   help="then drive in-process with the same seeds and check the logs are identical")
