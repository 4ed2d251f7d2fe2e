from povlens.cli import main

raise SystemExit(main())
