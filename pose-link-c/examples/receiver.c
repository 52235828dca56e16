/*
 * Pose-link receiver in C, on the pose-link-c static library (POSIX sockets: Linux, macOS).
 *
 *   receiver udp PORT COUNT    bind 127.0.0.1:PORT (0: any free port), receive COUNT datagrams,
 *                              decode each one with pose_link_decode
 *   receiver serial FILE|-     read a serial byte stream (COBS frames, 0x00-delimited) from a
 *                              file or stdin through the deframer
 *
 * Output, stdout, one line each:
 *   listening udp 127.0.0.1:PORT                        (udp, before the first datagram)
 *   pose SEQ T X Y Z QW QX QY QZ ESTIMATOR FLAGS        (T: measurement time [s]; FLAGS: hex)
 *   errors NAME=COUNT ...                               (every error status, zero or not)
 *   counters bytes_in=... messages_ok=... ...           (serial: the deframer's counters)
 * Exit status 0; 1 on bad usage or I/O errors; 2 when no datagram came for 30 s.
 *
 * Build (see docs/pose-link.md):
 *   cargo build --release -p pose-link-c
 *   cc -Ipose-link-c/include pose-link-c/examples/receiver.c \
 *      target/release/libpose_link_c.a -lpthread -ldl -lm -o receiver
 */
#include "pose_link.h"

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

/* Status codes are small and dense; count each one. */
#define N_STATUS 32
static unsigned long counts[N_STATUS];

static void count(int32_t status) {
    counts[(status >= 0 && status < N_STATUS) ? status : N_STATUS - 1]++;
}

static const char *estimator_name(uint8_t e) {
    switch (e) {
    case POSE_LINK_ESTIMATOR_MODEL:
        return "model";
    case POSE_LINK_ESTIMATOR_DOPPLER:
        return "doppler";
    case POSE_LINK_ESTIMATOR_IMU:
        return "imu";
    case POSE_LINK_ESTIMATOR_FUSED:
        return "fused";
    default:
        return "unknown";
    }
}

static void print_pose(const PoseLinkPose *p) {
    /* The time exactly, from the integer nanoseconds; the position and quaternion with the
       precision `milliego run`'s TUM output uses. */
    printf("pose %u %llu.%09llu %.6f %.6f %.6f %.9f %.9f %.9f %.9f %s 0x%04x\n", p->seq,
           (unsigned long long)(p->measurement_time_ns / 1000000000u),
           (unsigned long long)(p->measurement_time_ns % 1000000000u), p->position[0],
           p->position[1], p->position[2], p->orientation[0], p->orientation[1],
           p->orientation[2], p->orientation[3], estimator_name(p->estimator), p->health);
}

static void print_errors(void) {
    printf("errors");
    /* Every status but Ok and NeedMore is an error; pose_link_status_name names them. */
    for (int32_t s = 1; s < POSE_LINK_STATUS_NEED_MORE; s++)
        printf(" %s=%lu", pose_link_status_name(s), counts[s]);
    printf("\n");
}

static int run_udp(unsigned port, unsigned long n) {
    int fd = socket(AF_INET, SOCK_DGRAM, 0);
    if (fd < 0) {
        perror("socket");
        return 1;
    }
    struct sockaddr_in addr;
    memset(&addr, 0, sizeof addr);
    addr.sin_family = AF_INET;
    addr.sin_port = htons((uint16_t)port);
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (bind(fd, (struct sockaddr *)&addr, sizeof addr) != 0) {
        perror("bind");
        return 1;
    }
    /* A large receive buffer, so a sender running flat out loses nothing on loopback. */
    int rcvbuf = 4 << 20;
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    struct timeval tv = {30, 0};
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    socklen_t alen = sizeof addr;
    getsockname(fd, (struct sockaddr *)&addr, &alen);
    printf("listening udp 127.0.0.1:%u\n", (unsigned)ntohs(addr.sin_port));
    fflush(stdout);

    /* Larger than any message: a too-long datagram is seen whole and rejected as too_long. */
    uint8_t buf[2048];
    for (unsigned long i = 0; i < n; i++) {
        ssize_t len = recv(fd, buf, sizeof buf, 0);
        if (len < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK) {
                fprintf(stderr, "receiver: no datagram for 30 s (%lu of %lu received)\n", i, n);
                print_errors();
                return 2;
            }
            perror("recv");
            return 1;
        }
        PoseLinkPose pose;
        PoseLinkStatus s = pose_link_decode(buf, (size_t)len, &pose);
        count(s);
        if (s == POSE_LINK_STATUS_OK)
            print_pose(&pose);
        else
            fprintf(stderr, "receiver: datagram %lu (%zd B) dropped: %s\n", i, len,
                    pose_link_status_name(s));
    }
    close(fd);
    print_errors();
    return 0;
}

static void on_pose(void *user, const PoseLinkPose *pose) {
    (void)user;
    count(POSE_LINK_STATUS_OK);
    print_pose(pose);
}

static void on_error(void *user, PoseLinkStatus status) {
    (void)user;
    count(status);
}

static int run_serial(const char *path) {
    FILE *f = strcmp(path, "-") == 0 ? stdin : fopen(path, "rb");
    if (!f) {
        perror(path);
        return 1;
    }
    /* Caller-allocated: the deframer lives here, on the stack; no allocation anywhere. */
    PoseLinkDeframer d;
    if (pose_link_deframer_init(&d) != POSE_LINK_STATUS_OK) {
        fprintf(stderr, "receiver: deframer init failed\n");
        return 1;
    }
    /* Small reads on purpose: frames straddle the chunks, as they do on a UART. */
    uint8_t chunk[61];
    size_t n;
    while ((n = fread(chunk, 1, sizeof chunk, f)) > 0) {
        PoseLinkStatus s = pose_link_deframer_push(&d, chunk, n, on_pose, on_error, NULL);
        if (s != POSE_LINK_STATUS_OK) {
            fprintf(stderr, "receiver: push failed: %s\n", pose_link_status_name(s));
            return 1;
        }
    }
    if (ferror(f)) {
        perror(path);
        return 1;
    }
    PoseLinkDeframerCounters c;
    pose_link_deframer_counters(&d, &c);
    print_errors();
    printf("counters bytes_in=%llu messages_ok=%llu frames_bad_cobs=%llu frames_bad_message=%llu "
           "frames_overflow=%llu bytes_dropped=%llu empty_frames=%llu\n",
           (unsigned long long)c.bytes_in, (unsigned long long)c.messages_ok,
           (unsigned long long)c.frames_bad_cobs, (unsigned long long)c.frames_bad_message,
           (unsigned long long)c.frames_overflow, (unsigned long long)c.bytes_dropped,
           (unsigned long long)c.empty_frames);
    if (f != stdin)
        fclose(f);
    return 0;
}

int main(int argc, char **argv) {
    if (pose_link_version() != POSE_LINK_VERSION || pose_link_message_len() != POSE_LINK_MESSAGE_LEN) {
        fprintf(stderr, "receiver: header and library disagree\n");
        return 1;
    }
    if (argc == 4 && strcmp(argv[1], "udp") == 0)
        return run_udp((unsigned)strtoul(argv[2], NULL, 10), strtoul(argv[3], NULL, 10));
    if (argc == 3 && strcmp(argv[1], "serial") == 0)
        return run_serial(argv[2]);
    fprintf(stderr, "usage: %s udp PORT COUNT | serial FILE|-\n", argv[0]);
    return 1;
}
