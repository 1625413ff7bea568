# One image for every hri-fusion process: the router (`python -m hri.cli router`) and each service
# (`python -m services.<name>`); docker-compose.yml picks the command.
#
# Python packages come from docker/wheels/ when docker/fetch-wheels.sh has filled it (no network needed
# during the build), else from the package index. Where no registry is reachable, docker/build-base-image.sh
# makes a local python:3.11-slim. docker/ci.sh does all of it.
FROM python:3.11-slim

# Extras of pyproject.toml installed in the image (docker/fetch-wheels.sh reads this line).
ARG HRI_EXTRAS=gesture,vision,speech,record,ros2

ENV PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_ROOT_USER_ACTION=ignore

WORKDIR /app

# Dependencies first, in their own layer: a code change does not reinstall them.
COPY pyproject.toml constraints.txt ./
COPY docker/project-requirements.py docker/install-python-packages.sh docker/
# The wheels are bind-mounted, not copied: they would stay in a layer (200 MB) even if deleted later.
RUN --mount=type=bind,source=docker/wheels,target=/tmp/wheels \
    sh docker/install-python-packages.sh "$HRI_EXTRAS" /tmp/wheels

# The code. README.md is optional here (pyproject names it; the build only needs it to exist).
COPY common/ common/
COPY services/ services/
COPY hri/ hri/
# the ROS 2 message definitions the ros2 service (compose profile ros2) reads
COPY ros2/ ros2/
# the example robot profiles (hri-fusion --profile /app/profiles/NAME.toml, docs/robot.md)
COPY profiles/ profiles/
COPY docker/healthcheck.py docker/
RUN touch README.md && pip install --no-deps --no-build-isolation --no-index -q . \
    && python -c "import hri.cli, services" \
    && useradd --system --create-home --home-dir /home/hri hri

# Inputs (photos, WAVs) are bind-mounted read-only at /data by docker-compose.yml (no VOLUME here: it
# would leave an anonymous volume behind for every container that does not mount one).
USER hri
EXPOSE 7447
CMD ["python", "-m", "hri.cli", "--help"]
