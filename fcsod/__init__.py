"""fcsod: the print-server daemon that runs fcso on every complete print-job folder.

It watches job folders, designs fingers with :mod:`fcso`'s public API, places
them into the job's build volume, publishes results over Eclipse Zenoh and
records each job to MCAP.

A cell controller checks every message it receives with
``fcsod.verify_message(key_expr, payload, attachment, fcsod.load_verify_key("signing.pub"))``
(see :mod:`fcsod.bus.signing`).
"""

__version__ = "0.1.0"

__all__ = ["SignatureError", "load_verify_key", "verify_message"]


def __getattr__(name: str):
    # imported on first use: workers and the CLI do not pay for the crypto imports they do not need
    if name in __all__:
        from .bus import signing

        return getattr(signing, name)
    raise AttributeError(f"module 'fcsod' has no attribute {name!r}")
