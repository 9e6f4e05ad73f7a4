"""The package's version, in a module that imports nothing: every part that reports it
(the CLI, the service, the request headers, hand-carry files) imports it from here, so
none of them depends on the package's top."""

__version__ = "0.2.0"
