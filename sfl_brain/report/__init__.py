"""``sfl report``: one HTML page for one or more run folders. :mod:`.report` picks the page by what the runs hold;
each kind of page has its file (:mod:`.ch5`, :mod:`.conditions`, :mod:`.cpg`, :mod:`.study`, :mod:`.sweep`,
:mod:`.terrain`), with the statistics (:mod:`.stats`) and return maps (:mod:`.poincare`) they use. A report only
reads run folders (records, Rerun logs) and studies; nothing imports it but the command line.
"""

from .._moved import forward

__getattr__ = forward(__name__, __name__ + ".report")  # ``sfl_brain.report.X`` of before issue 30 is ``.report.X``
