"""The configuration's floor: the settings toolkit (a key's type, default, doc and limits; the table checker),
the validated configuration's types, the demo defaults, the sensors' registry and the start checks' finding.

Every settings module imports from here; this room imports no device, source, recipe, store or publisher, so
the assembler (``service.config``) can sit above them all.
"""
