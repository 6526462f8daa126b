/*
 * send_example.c: sends N observations of a ball flying down the table to
 * topspin's tracker port through ttb1.h (a wiring check, and the test's C
 * sender).  cc -O2 -o ttb1-send send_example.c && ./ttb1-send 127.0.0.1 41000 200
 */
#include <arpa/inet.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "ttb1.h"

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: %s HOST PORT COUNT\n", argv[0]);
        return 2;
    }
    struct sockaddr_in to = {0};
    to.sin_family = AF_INET;
    to.sin_port = htons((uint16_t)atoi(argv[2]));
    if (inet_pton(AF_INET, argv[1], &to.sin_addr) != 1) {
        fprintf(stderr, "%s: not an IPv4 address\n", argv[1]);
        return 2;
    }
    int count = atoi(argv[3]);
    int fd = socket(AF_INET, SOCK_DGRAM, 0);
    if (fd < 0) {
        perror("socket");
        return 1;
    }
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    uint64_t start = (uint64_t)now.tv_sec * 1000000000u + (uint64_t)now.tv_nsec;
    for (int k = 0; k < count; k++) {
        double t = fmod(k * 0.005, 0.6); /* 200 Hz */
        ttb1_observation o = {
            .seq = (uint32_t)k,
            .capture_ns = start + (uint64_t)k * 5000000u,
            .x = (float)(-1.6 + 5.0 * t),
            .y = 0.05f,
            .z = (float)fmax(0.02, 0.35 + 0.8 * t - 4.905 * t * t),
            .residual = 0.001f,
            .cameras = 3,
            .flags = TTB1_FLAG_VALID,
        };
        uint8_t buf[TTB1_LEN];
        ttb1_encode(&o, buf);
        if (sendto(fd, buf, sizeof buf, 0, (struct sockaddr *)&to, sizeof to) != TTB1_LEN) {
            perror("sendto");
            return 1;
        }
        struct timespec gap = {0, 5000000};
        nanosleep(&gap, NULL);
    }
    close(fd);
    printf("sent %d TTB1 observations to %s:%s\n", count, argv[1], argv[2]);
    return 0;
}
