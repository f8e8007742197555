"""intuitf.intent: what the user's words, pictures and strokes ask for.

The judge and the explorer both read intent; neither the renderer nor a model is needed here.
Modules: :mod:`~intuitf.intent.colours` (named colours), :mod:`~intuitf.intent.aspects`
(aspect catalogues), :mod:`~intuitf.intent.hints` (words to materials and colours),
:mod:`~intuitf.intent.palette` (colours of a reference picture), :mod:`~intuitf.intent.selection`
(selected features and edits).
"""
