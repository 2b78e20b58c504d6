"""The built-in measurement kinds, one folder each (``hostpc/kinds/<name>/``).

A folder holds everything about its kind: the file face (``file_face.py``), the prediction
and Jacobian (``model.py``), the pure planning (``planning``), the acquisition method
(``method.py``, the only I/O) and, in its ``__init__``, the one ``KindDescriptor`` (``KIND``)
that registers it. zerocal publishes each ``KIND`` as an entry point of the group
``zerocal.measurements`` (pyproject.toml), the way a plugin package would: the generic
layers (dataset, model, fitting, diagnostics, planning, report) never import this package
(an import contract checks it) and find the kinds through ``hostpc.dataset.kind_registry``.
"""
