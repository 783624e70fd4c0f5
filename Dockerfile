# DriftLab: docker build -t driftlab . && docker run -p 8000:8000 -e DRIFTLAB_TOKEN=<secret> -v driftlab-data:/data driftlab
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 \
    NUMBA_CACHE_DIR=/opt/driftlab/numba-cache DRIFTLAB_DATABASE_URL=sqlite:////data/driftlab.db

WORKDIR /opt/driftlab
COPY requirements ./requirements
# The lock first (its layer is cached while only the code changes), then the package without resolving anything.
RUN pip install --no-cache-dir -r requirements/app.txt
COPY pyproject.toml README.md ./
COPY driftlab ./driftlab
RUN pip install --no-cache-dir --no-deps --no-build-isolation . \
    && useradd --create-home --uid 1000 driftlab \
    && mkdir -p /data "$NUMBA_CACHE_DIR" \
    # Warm the numba cache at build time: the first episode would otherwise compile for ~5 s, the first ask ~3 s.
    && driftlab episode --plant nominal --controller paper > /dev/null && driftlab episode > /dev/null \
    && python -c "from driftlab.core.acquisition_gradient import warm_up; warm_up()" \
    && chown -R driftlab /data "$NUMBA_CACHE_DIR"

USER driftlab
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s \
    CMD python -c "import urllib.request,sys; sys.exit(urllib.request.urlopen('http://127.0.0.1:8000/api/health').status != 200)"
# The same command the README runs, on all interfaces so the published port reaches it: `serve` refuses that without
# DRIFTLAB_TOKEN (docker run -e DRIFTLAB_TOKEN=...), so a published port never hands the API to anyone who reaches it.
CMD ["driftlab", "serve", "--host", "0.0.0.0", "--port", "8000"]
