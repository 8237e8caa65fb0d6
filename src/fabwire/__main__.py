"""`python -m fabwire` and the console script."""

import os
import signal
import sys

_INTERRUPTED = b"fabwire: interrupted\n"
_EXIT_INTERRUPTED = 130  # fabwire.errors.EXIT_INTERRUPTED, not imported: this must hold before any import


def _interrupted_while_starting(signum: int, frame: object) -> None:
    # Nothing has been printed or opened yet: leave at once rather than unwind half-done imports into a traceback.
    os.write(2, _INTERRUPTED)
    os._exit(_EXIT_INTERRUPTED)


# numpy's OpenBLAS starts a thread per core when it loads, which costs a command more CPU than reading a 10 MB
# G-code; fabwire does no linear algebra worth a second thread. A value the user set is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# Set on import: this module is only ever the entry point, and the CLI's imports come next.
_catching = signal.getsignal(signal.SIGINT) is signal.default_int_handler  # an ignored Ctrl-C stays ignored
if _catching:
    signal.signal(signal.SIGINT, _interrupted_while_starting)


def _interrupt_from_finaliser(unraisable: "sys.UnraisableHookArgs") -> None:
    # A Ctrl-C that lands while a finaliser runs (an event loop's __del__ as a link closes) cannot be raised there,
    # and Python would print it as a traceback: raise it again in the main thread, where commands handle it, once
    # this hook has returned (raised from here, it would land in the hook itself).
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        import _thread
        import threading

        threading.Timer(0.01, _thread.interrupt_main).start()
        return
    sys.__unraisablehook__(unraisable)


def run() -> None:
    from fabwire.console import StdoutClosed, guard_stdout, stdout_closed

    guard_stdout()
    try:
        if sys.argv[1:] in (["--version"], ["-V"]):  # answered before click and the CLI are imported
            from fabwire import __version__

            sys.stdout.write(f"fabwire, version {__version__}\n")
            code = 0
        else:
            from fabwire.importing import collection_paused

            with collection_paused():
                from fabwire.cli import main
            if _catching:  # from here on commands clean up on KeyboardInterrupt (links, partial files)
                signal.signal(signal.SIGINT, signal.default_int_handler)
                sys.unraisablehook = _interrupt_from_finaliser
            code = main()
    except KeyboardInterrupt:  # between the handler's return and main's own handling
        sys.stderr.write(_INTERRUPTED.decode())
        code = _EXIT_INTERRUPTED
    except StdoutClosed:  # the reader of the output went away (`| head`): nothing more to say, not an error
        code = stdout_closed()
    sys.exit(code)


if __name__ == "__main__":
    run()
