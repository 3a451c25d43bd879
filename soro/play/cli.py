"""``soro play SCENE``: build the scene, make the back end, serve the page (the handler of the ``play``
subcommand of :mod:`sorofem.cli`; exit codes in :mod:`soro.play`)."""
from __future__ import annotations

import sys
import time

__all__ = ["serve", "serve_mirror", "run", "EXIT_MISSING", "EXIT_SCENE", "EXIT_PORT", "EXIT_BOARD"]

EXIT_MISSING, EXIT_SCENE, EXIT_PORT, EXIT_BOARD = 2, 3, 4, 5


def serve(scene, backend="model", *, host="127.0.0.1", port=8765, board_url=None, secret=None, secret_file=None,
          out="out/play", clock=None):
    """Start serving ``scene`` (a :class:`~soro.play.Scene`, Shapes or Model) and return the running
    :class:`~soro.play.PlayServer` (its ``url``; ``close()`` stops it and vents a board).

    ``backend``: ``"model"`` (real-time stepping here), ``"sim"`` (the simulated board with the model as plant)
    or ``"board"`` (a real board at ``board_url`` with ``secret`` or ``secret_file``)."""
    from sorofem.errors import ParameterError

    from .backends import BoardBackend, ModelBackend
    from .scene import as_scene
    from .server import PlayServer
    scene = as_scene(scene)
    if backend in ("sim", "board") and host not in ("127.0.0.1", "localhost", "::1"):
        raise ParameterError(f"a board back end serves on this machine only (--host 127.0.0.1): the page has no "
                             f"login, and anyone reaching {host} could drive the board")
    kw = {"out": out} if clock is None else {"out": out, "clock": clock}
    if backend not in ("model", "sim", "board"):
        raise ParameterError(f"backend must be 'model', 'sim' or 'board', got {backend!r}")
    if backend == "board" and not board_url:
        raise ParameterError("the board back end needs --board-url tcp://host:port (and --secret-file or "
                             "$SORO_BOARD_SECRET)")
    def make():
        if backend == "model":
            return ModelBackend(scene, **kw)
        board = None
        if backend == "board":
            from sorocontrol import Board
            board = Board.connect(board_url, secret=secret, secret_file=secret_file)
        return BoardBackend(scene, board=board, **kw)

    return PlayServer(scene, make, host=host, port=port).start()


def serve_mirror(model, inputs=None, *, host="127.0.0.1", port=0, title="gymnasium env"):
    """Serve the page of a :class:`soroshapes.Model` that its owner steps (the Gymnasium environment's
    ``render_mode="human"``): returns the running :class:`~soro.play.PlayServer`; call
    ``server.backend.update(u)`` after each step (``u``: the values of ``inputs``, free inputs of the model shown
    as read-only sliders; default all)."""
    from .backends import MirrorBackend
    from .scene import Scene, default_channel
    from .server import PlayServer
    names = list(model.inputs) if inputs is None else list(inputs)
    scene = Scene(model, [default_channel(n) for n in names], title=title)
    server = PlayServer(scene, lambda: MirrorBackend(scene), host=host, port=port).start()
    server.backend.update()
    return server


def run(args, stream=None, err=None):
    """The ``soro play`` handler: returns the exit status (see :mod:`soro.play`)."""
    stream, err = stream or sys.stdout, err or sys.stderr
    from sorofem.errors import ParameterError, ProtocolError, SoroError

    from .scene import SceneError, SceneNotFoundError, load_scene
    from .server import ServeError
    try:
        scene = load_scene(args.scene, quick=args.quick)
    except SceneNotFoundError as e:
        print(f"soro play: {e}", file=err)
        return EXIT_MISSING
    except SceneError as e:
        print(f"soro play: {e}", file=err)
        return EXIT_SCENE
    try:
        server = serve(scene, args.backend, host=args.host, port=args.port, board_url=args.board_url,
                       secret_file=args.secret_file, out=args.out)
    except ServeError as e:
        print(f"soro play: {e}", file=err)
        return EXIT_PORT
    except ProtocolError as e:
        print(f"soro play: cannot reach the board: {e}", file=err)
        return EXIT_BOARD
    except ParameterError as e:
        print(f"soro play: {e}", file=err)
        return EXIT_MISSING
    except SoroError as e:
        print(f"soro play: {e}", file=err)
        return EXIT_SCENE
    print(f"soro play: {scene.title} ({args.backend} back end) at {server.url}  (Ctrl-C stops and vents)",
          file=stream, flush=True)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"soro play: warning: serving on {args.host}: anyone who reaches it can drive the scene", file=err)
    if args.open:
        import webbrowser
        webbrowser.open(server.url)
    try:
        end = None if args.duration is None else time.monotonic() + args.duration
        while end is None or time.monotonic() < end:
            time.sleep(0.2 if end is None else max(0.0, min(0.2, end - time.monotonic())))
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    print("soro play: stopped", file=stream, flush=True)
    return 0
