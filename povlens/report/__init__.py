"""Reports on renders: error metrics between images (``compare``) and the HTML page
about render folders (``html``)."""
