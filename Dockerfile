# shapebag container image: `docker compose up -d --build --wait` (see docs/deploy.md).
#
# Any Debian-like image with Python >= 3.11 and venv works as the base; where no registry is reachable use
# the locally built one:  docker build --build-arg BASE_IMAGE=localhost/debian-python:bookworm -t shapebag .
# The base's pip settings (PIP_CERT, SSL_CERT_FILE: a proxy CA) are inherited by every stage, untouched.
#
# Layers of the final image, slowest-changing first: base, user, the dependencies' venv (~370 MB, rebuilt only
# when the lock changes), then the shapebag package itself (< 1 MB: all a code change rebuilds, ships
# and pulls).
ARG BASE_IMAGE=python:3.12-slim
# the optional extra of pyproject.toml to install: `postgres` (psycopg + psycopg_pool) for
# SHAPEBAG_DATABASE_URL=postgresql://... (docker-compose.scale.yml builds with it); empty: none
ARG EXTRAS=""

# ---- deps: a virtual environment with the dependencies only, keyed on the lock of EXTRAS ----
FROM ${BASE_IMAGE} AS deps
ARG EXTRAS
ENV PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PATH=/opt/venv/bin:$PATH
RUN python3 -m venv /opt/venv
WORKDIR /src
COPY requirements/ ./requirements/
# The exact versions CI tested: requirements/base.lock, or <EXTRAS>.lock (`make lock` writes them from
# pyproject.toml's ranges), every file checked against its hash. The build backend comes after, for the
# `package` stage only. The libraries' own test suites (~70 MB) are never imported at runtime. The .pth puts
# the package directory (filled by the `package` stage) on the venv's path.
RUN lock="requirements/${EXTRAS:-base}.lock" \
    && { [ -f "$lock" ] || { echo "no $lock: EXTRAS is empty or one of base, postgres, dev" >&2; exit 1; }; } \
    && pip install --prefer-binary --require-hashes -r "$lock" \
    && pip install "setuptools>=77,<100" "wheel>=0.43,<1" \
    && find /opt/venv -type d -name tests -prune -exec rm -rf {} + \
    && echo /opt/shapebag/lib > "$(python3 -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/shapebag.pth"

# ---- venv: the same without pip and the build backend, which have no use at runtime ----
FROM deps AS venv
RUN pip uninstall -q -y setuptools wheel pip

# ---- package: shapebag alone (no deps) into /opt/shapebag/lib, with its `shapebag` script and its package
# data: the web page and the shipped default vocabulary (app/data/vocabulary/default, found through
# importlib.resources exactly as in a wheel or editable install) ----
FROM deps AS package
# README.md* : optional (pyproject names it as the long description when present)
COPY pyproject.toml README.md* ./
COPY app/ ./app/
# no build isolation: the build backend is already in the venv, so a code-only rebuild needs no network
# chmod: a vocabulary saved locally may be 0700 (a private temp dir). -P: import the installed app, not ./app
RUN pip install --no-deps --no-build-isolation --target /opt/shapebag/lib . \
    && chmod -R a+rX,go-w /opt/shapebag/lib \
    && python3 -P -c "from app.config import SHIPPED_VOCABULARY as v; assert (v / 'vocabulary.json').is_file(), v"

# ---- runtime: base + venv + package; no pip, no build tools, no sources, no compiler ----
FROM ${BASE_IMAGE}
ENV PATH=/opt/shapebag/lib/bin:/opt/venv/bin:$PATH \
    PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    SHAPEBAG_DATA_DIR=/data
# a fixed uid so that files on the /data volume keep one owner across rebuilds
RUN groupadd --gid 10001 shapebag \
    && useradd --uid 10001 --gid shapebag --no-log-init --no-create-home --home-dir /opt/shapebag \
        --shell /usr/sbin/nologin shapebag \
    && mkdir -p /data /opt/shapebag \
    && chown shapebag:shapebag /data
COPY --from=venv /opt/venv /opt/venv
COPY --from=package /opt/shapebag/lib /opt/shapebag/lib
WORKDIR /opt/shapebag
USER 10001:10001
VOLUME /data
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=5s --start-period=60s --retries=3 \
    CMD ["python3", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/healthz' % os.environ.get('SHAPEBAG_PORT', '8000'), timeout=4)"]
CMD ["shapebag", "serve", "--host", "0.0.0.0"]
