"""`noisebo instruments` and `policies`: what is installed."""

from __future__ import annotations


def _policies_listed(args) -> int:
    from noisebo import registry

    for group, title in (
        (registry.POLICIES, "policies (acquisition.policy)"),
        (registry.NOISE_LAWS, "noise laws (noise_model.mean)"),
    ):
        print(f"{title}:")
        for name, found in registry.installed(group).items():
            where = f"{found.distribution} {found.distribution_version}"
            try:
                doc = (type(registry.load(group, name)).__doc__ or "").strip().splitlines()
                print(f"  {name:<18} {where}: {doc[0] if doc else ''}".rstrip())
            except registry.PluginBroken as error:
                print(f"  {name:<18} {where}: BROKEN: {error}")
    return 0


def _instruments(args) -> int:
    from noisebo.config import lax_fields
    from noisebo.instruments.registry import DriverBroken, driver_class, installed

    for name, found in installed().items():
        try:
            cls = driver_class(name)
            doc = (cls.__doc__ or "").strip().splitlines()
            version = cls.version
            fields = ", ".join(cls.Settings.model_fields)
            line = (
                f"{name:<16} {version:<10} {found.distribution} {found.distribution_version}: {doc[0] if doc else ''}"
            )
            print(line.rstrip())
            print(f"{'':<16} settings: {fields or '(none)'}")
            lax = lax_fields(cls.Settings)
            if lax:
                print(f"{'':<16} checked strictly by noisebo (the driver's own model is lax): {', '.join(lax)}")
        except DriverBroken as error:
            print(f"{name:<16} {'?':<10} {found.distribution} {found.distribution_version}: BROKEN: {error}")
    return 0


def add_parser(commands) -> None:
    """The group's commands, on ``commands`` (the subparsers of ``noisebo``)."""
    instruments = commands.add_parser("instruments", help="list the installed instrument drivers")
    instruments.set_defaults(handler=_instruments)

    policies = commands.add_parser("policies", help="list the installed policies and noise laws")
    policies.set_defaults(handler=_policies_listed)
