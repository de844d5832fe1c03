"""fcsod: the print-server daemon that runs fcso on every complete print-job folder.

It watches job folders, designs fingers with :mod:`fcso`'s public API, places
them into the job's build volume, publishes results over Eclipse Zenoh and
records each job to MCAP.
"""

__version__ = "0.1.0"
