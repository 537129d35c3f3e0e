"""Ctrl-C while one of tmmaster's commands is still loading: one line and exit 130.

Imported first by ``tmmaster/__init__.py``. It acts only when this process *is* one of
tmmaster's commands (``python -m tmmaster``, ``-m tmmaster.pickplace``, ``.sim``,
``.report``, ``.tmscript``, or the ``tmmaster`` console script): until the command's
``main()`` takes Ctrl-C over (:func:`tmmaster._sigint.run_main`), a Ctrl-C ends the
process at once with one line and exit 130. Nothing is connected or started while the
package loads, so there is nothing to clean up. A program that imports tmmaster is left
alone: its Ctrl-C handling is its own.

A Ctrl-C before the first line of tmmaster runs (Python's own start-up: ``site``, the
``-m`` machinery) is Python's: its usual ``KeyboardInterrupt`` traceback.
"""

# Only modules Python's start-up has loaded (``_signal`` is the C module under
# ``signal``): nothing to load before the handler is in place.
import _signal  # type: ignore[import-not-found]  # no stubs: the C module under signal
import os
import sys

#: Entry modules of the commands, and the name each prints its messages under.
_COMMANDS = {
    "tmmaster.__main__": "tmmaster",
    "tmmaster.pickplace.__main__": "pickplace",
    "tmmaster.report.__main__": "report",
    "tmmaster.sim.__main__": "sim",
    "tmmaster.tmscript.__main__": "tmscript",
}

#: Exit status of an interrupted command (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130


def _command_name() -> str | None:
    """The command this process runs, or None when it is another program."""
    argv = getattr(sys, "orig_argv", [])
    if "-m" in argv[:-1]:
        # ``python -m tmmaster.pickplace``: runpy imports the packages before __main__
        # exists; the command line already says which module runs.
        return _COMMANDS.get(f"{argv[argv.index('-m') + 1]}.__main__")
    main = sys.modules.get("__main__")
    script = sys.argv[0] if sys.argv else ""
    # The console script: its wrapper is __main__, the file argv[0] names.
    if os.path.basename(script) == "tmmaster" and getattr(main, "__file__", None) == script:
        return "tmmaster"
    return None


def _install() -> None:
    name = _command_name()
    if name is None or _signal.getsignal(_signal.SIGINT) == _signal.SIG_IGN:
        return  # another program; or a command started with Ctrl-C ignored (``cmd &``)

    def interrupted(_signum: int, _frame: object) -> None:
        os.write(2, f"{name}: interrupted [exit {EXIT_INTERRUPTED}]\n".encode())
        os._exit(EXIT_INTERRUPTED)

    try:
        _signal.signal(_signal.SIGINT, interrupted)
    except ValueError:  # imported in another thread than the main one
        return
    if os.environ.get("TMMASTER_TEST_SIGINT_AT") == "import":
        # Test hook: say so and wait for a byte on stdin (a test's Ctrl-C lands here).
        os.write(2, b"tmmaster-test: paused at import\n")
        os.read(0, 1)


_install()
