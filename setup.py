"""The one compiled module of astrodyn (everything else is in pyproject.toml).

``astrodyn.messages.floatlayout`` lays JSON floats out as ``repr(float)`` does; its C file
says why it is compiled.  It is optional: without a C compiler the package installs without
it and ``astrodyn.messages.codec`` writes the same bytes by its Python path.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("astrodyn.messages.floatlayout", ["src/astrodyn/messages/floatlayout.c"], optional=True)])
