from noisebo.cli.main import main

raise SystemExit(main())
