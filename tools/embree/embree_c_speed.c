/* Casts the rays that tools/src/bin/ray-speed.rs cast, with Intel Embree 3's own C API on one
 * thread, in its two modes: one ray at a time (rtcIntersect1) and coherent packets of 4 x 4 rays
 * (rtcIntersect16 over 4 x 4 texel tiles, with the coherent flag: 16 rays is the widest packet
 * Embree's API takes; hdov's packets are its own shape, cpu::PACKET_TEXELS). Checks the hit objects against hdov's id cubes and prints both speeds beside hdov's.
 * Times are the process's CPU time, as hdov's are.
 *
 *   cc -O2 -march=native tools/embree/embree_c_speed.c -lembree3 -o embree_c_speed
 *   ./embree_c_speed OUT_DIR          (after `ray-speed SCENE OUT_DIR`; ray_speed.sh does both)
 *
 * Needs Debian's libembree-dev (Embree 3.13). Same triangles (hdov's world triangles, unshared
 * vertices), origins, texel-centre directions (forward component 1, not normalised), rays from
 * hdov's near distance, first hit, BVH built at RTC_BUILD_QUALITY_HIGH. */
#include <embree3/rtcore.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define NO_OBJECT 0xFFFFFFFFu
#define BACK_FACE_BIT 0x80000000u

static void *slurp(const char *dir, const char *name, size_t *len) {
  char path[4096];
  snprintf(path, sizeof path, "%s/%s", dir, name);
  FILE *f = fopen(path, "rb");
  if (!f) { fprintf(stderr, "%s: cannot open\n", path); exit(2); }
  fseek(f, 0, SEEK_END);
  *len = (size_t)ftell(f);
  fseek(f, 0, SEEK_SET);
  void *data = malloc(*len + 1);
  if (fread(data, 1, *len, f) != *len) { fprintf(stderr, "%s: short read\n", path); exit(2); }
  ((char *)data)[*len] = 0;
  fclose(f);
  return data;
}

/* The number after "key": in hdov.json (flat, written by ray-speed). */
static double json_number(const char *json, const char *key) {
  char pattern[128];
  snprintf(pattern, sizeof pattern, "\"%s\":", key);
  const char *at = strstr(json, pattern);
  if (!at) { fprintf(stderr, "hdov.json: no %s\n", key); exit(2); }
  return strtod(at + strlen(pattern), NULL);
}

static double cpu_seconds(void) {
  struct timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int main(int argc, char **argv) {
  if (argc != 2) { fprintf(stderr, "usage: embree_c_speed OUT_DIR\n"); return 2; }
  const char *dir = argv[1];
  size_t len;
  char *meta = slurp(dir, "hdov.json", &len);
  const int r = (int)json_number(meta, "resolution");
  const float near_t = (float)json_number(meta, "near");
  const float *tris = slurp(dir, "triangles.f32", &len);
  const size_t ntris = len / (9 * sizeof(float));
  const uint32_t *objects = slurp(dir, "objects.u32", &len);
  const float *points = slurp(dir, "points.f32", &len);
  const size_t npoints = len / (3 * sizeof(float));
  const float *dirs = slurp(dir, "directions.f32", &len);
  const size_t rays = len / (3 * sizeof(float));
  const uint32_t *ids = slurp(dir, "ids.u32", &len);
  if (rays != (size_t)6 * r * r || len != npoints * rays * 4) { fprintf(stderr, "files do not agree\n"); return 2; }

  /* EMBREE_MAX_ISA (e.g. avx2) caps Embree's kernels, to compare at hdov's vector width. */
  char config[128];
  const char *max_isa = getenv("EMBREE_MAX_ISA");
  snprintf(config, sizeof config, "threads=1%s%s", max_isa ? ",max_isa=" : "", max_isa ? max_isa : "");
  RTCDevice device = rtcNewDevice(config);
  printf("embree device config: %s\n", config);
  RTCScene scene = rtcNewScene(device);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  float *vb = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * ntris);
  unsigned *ib = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), ntris);
  memcpy(vb, tris, ntris * 9 * sizeof(float));
  for (size_t i = 0; i < 3 * ntris; i++) ib[i] = (unsigned)i;
  rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_HIGH);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  double b0 = cpu_seconds();
  rtcCommitScene(scene);
  double build = cpu_seconds() - b0;

  uint32_t *single = malloc(rays * 4), *packet = malloc(rays * 4);
  double t_single = 0, t_packet = 0;
  size_t differ_single = 0, differ_packet = 0, hits = 0, packet_vs_single = 0;
  for (size_t p = 0; p < npoints; p++) {
    const float *o = points + 3 * p;
    /* One ray at a time. */
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    double c0 = cpu_seconds();
    for (size_t i = 0; i < rays; i++) {
      struct RTCRayHit rh;
      rh.ray.org_x = o[0]; rh.ray.org_y = o[1]; rh.ray.org_z = o[2];
      rh.ray.dir_x = dirs[3 * i]; rh.ray.dir_y = dirs[3 * i + 1]; rh.ray.dir_z = dirs[3 * i + 2];
      rh.ray.tnear = near_t; rh.ray.tfar = INFINITY; rh.ray.time = 0; rh.ray.mask = 0xFFFFFFFFu;
      rh.ray.id = 0; rh.ray.flags = 0;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &ctx, &rh);
      single[i] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? NO_OBJECT : objects[rh.hit.primID];
    }
    t_single += cpu_seconds() - c0;
    /* Coherent 4 x 4 packets: texel tiles of each face. */
    struct RTCIntersectContext coherent;
    rtcInitIntersectContext(&coherent);
    coherent.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    int valid[16];
    for (int k = 0; k < 16; k++) valid[k] = -1;
    c0 = cpu_seconds();
    for (int face = 0; face < 6; face++) {
      for (int row = 0; row < r; row += 4) {
        for (int col = 0; col < r; col += 4) {
          RTC_ALIGN(64) struct RTCRayHit16 rh;
          for (int k = 0; k < 16; k++) {
            size_t i = (size_t)face * r * r + (size_t)(row + k / 4) * r + (size_t)(col + k % 4);
            rh.ray.org_x[k] = o[0]; rh.ray.org_y[k] = o[1]; rh.ray.org_z[k] = o[2];
            rh.ray.dir_x[k] = dirs[3 * i]; rh.ray.dir_y[k] = dirs[3 * i + 1]; rh.ray.dir_z[k] = dirs[3 * i + 2];
            rh.ray.tnear[k] = near_t; rh.ray.tfar[k] = INFINITY; rh.ray.time[k] = 0;
            rh.ray.mask[k] = 0xFFFFFFFFu; rh.ray.id[k] = 0; rh.ray.flags[k] = 0;
            rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
          }
          rtcIntersect16(valid, scene, &coherent, &rh);
          for (int k = 0; k < 16; k++) {
            size_t i = (size_t)face * r * r + (size_t)(row + k / 4) * r + (size_t)(col + k % 4);
            packet[i] = rh.hit.geomID[k] == RTC_INVALID_GEOMETRY_ID ? NO_OBJECT : objects[rh.hit.primID[k]];
          }
        }
      }
    }
    t_packet += cpu_seconds() - c0;
    const uint32_t *h = ids + p * rays;
    for (size_t i = 0; i < rays; i++) {
      uint32_t want = h[i] == NO_OBJECT ? NO_OBJECT : (h[i] & ~BACK_FACE_BIT);
      hits += h[i] != NO_OBJECT;
      differ_single += single[i] != want;
      differ_packet += packet[i] != want;
      packet_vs_single += packet[i] != single[i];
    }
  }
  const double n = (double)npoints, ms1 = 1e3 * t_single / n, ms16 = 1e3 * t_packet / n;
  const double ms_fast = json_number(meta, "ms_per_point_fast"), ms_ray = json_number(meta, "ms_per_point_per_ray");
  printf("%zu points, R = %d, %zu triangles, %zu rays per point, one thread each; Embree BVH build %.2f s\n", npoints,
         r, ntris, rays, build);
  printf("embree C API, rtcIntersect1:              %.2f ms CPU per point, %.2f M rays/s\n", ms1, rays / ms1 / 1e3);
  printf("embree C API, coherent 4 x 4 rtcIntersect16: %.2f ms CPU per point, %.2f M rays/s\n", ms16, rays / ms16 / 1e3);
  printf("hdov render_ids, one ray at a time:       %.2f ms CPU per point\n", ms_ray);
  printf("hdov render_ids, ray packets:             %.2f ms CPU per point\n", ms_fast);
  printf("ratio hdov packets / embree: %.3f against rtcIntersect1, %.3f against coherent packets\n", ms_fast / ms1,
         ms_fast / ms16);
  printf("hit objects differing from hdov: %zu (single), %zu (packets) of %zu texels; hdov hit %zu; packets vs single %zu\n",
         differ_single, differ_packet, (size_t)(n * rays), hits, packet_vs_single);
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);
  return 0;
}
