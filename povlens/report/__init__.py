"""Reports on renders: error metrics between images (``compare``) and the HTML page
about render folders (``html``)."""

#: The page the HTML report (:func:`povlens.report.html.make_report`) is written to
#: when no other is named.
DEFAULT_REPORT = "report.html"
