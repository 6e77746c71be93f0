"""An instrument PC's loop as a Prefect flow run: the PC's instrument serves the shots a campaign's
bridge asks of it (``noisebo.bridge.client.serve_instrument``) until the campaign ends.

Deployed on a work pool of the PC's own (``noisebo deploy-instrument``), a worker on the PC runs
it: each instrument of a campaign of several has its flow run on its own pool, as the campaign's
flow run runs on the coordinator's. The token stays in a file on the PC; the flow's parameters
name the file, never the token."""

from pathlib import Path

from prefect import flow, get_run_logger

from noisebo.bridge.client import serve_instrument
from noisebo.bridge.serve_simulator import measure_with
from noisebo.config import ConfigError, load_config
from noisebo.flows.campaign import opened
from noisebo.flows.workers import deploy_from_checkout, ensure_process_pool
from noisebo.instruments import build
from noisebo.instruments.registry import validated


def read_token(token_file: str) -> str:
    """The bridge token in ``token_file`` (its first line); a one-line error when it cannot be read."""
    path = Path(token_file).expanduser()
    try:
        token = path.read_text().strip()
    except OSError as error:
        raise ConfigError(f"{token_file}: cannot read the bridge token ({error.strerror or error})") from None
    if not token:
        raise ConfigError(f"{token_file}: the bridge token file is empty")
    return token


@flow(name="instrument-pc", flow_run_name="{name}", persist_result=True, result_serializer="json")
def instrument_pc(
    name: str, url: str, config: str, token_file: str, pace: float = 0.0, cafile: str | None = None
) -> str:
    """Serve the instrument of ``config`` (a campaign config file: its ``instrument`` section is
    this PC's driver) to the campaign bridge at ``url`` as the instrument ``name``, with the
    token in ``token_file``, until the campaign ends; returns its final status. ``pace``: for a
    simulator, each shot takes pace x t seconds of real time; ``cafile``: the campaign's
    certificate for an ``https://`` url with a self-signed one."""
    token = read_token(token_file)
    instrument = build(validated(load_config(config), config).instrument)
    log = get_run_logger()
    log.info("instrument %s: %s serving %s", name, instrument.__class__.__name__, url)
    with opened(instrument):
        return serve_instrument(url, token, measure_with(instrument, pace), log=log.info, cafile=cafile)


def deploy_instrument_pc(
    name: str, url: str, config_path: str | Path, token_file: str | Path, pool: str, pace: float = 0.0
) -> str:
    """Register ``instrument-pc/NAME`` in the process work pool ``pool`` (the instrument PC's
    own): a run serves the instrument of ``config_path`` to the campaign bridge at ``url`` as the
    instrument ``name``, with the token in ``token_file`` (``instrument_pc``); its code
    taken from this checkout. Returns the deployment's full name."""
    ensure_process_pool(pool)
    parameters = {
        "name": name,
        "url": url,
        "config": str(Path(config_path).resolve()),
        "token_file": str(Path(token_file).expanduser().resolve()),
        "pace": pace,
    }
    description = f"instrument {name}'s PC serving the campaign at {url}, on the {pool} work pool"
    deploy_from_checkout(
        "noisebo/bridge/instrument_pc.py:instrument_pc",
        name,
        pool,
        parameters,
        description,
        ["noisebo", "instrument-pc", name],
    )
    return f"instrument-pc/{name}"
