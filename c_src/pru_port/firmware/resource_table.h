/*
 * Resource table for PRU0: one vdev (rpmsg) with two vrings, and the
 * interrupt mapping remoteproc programs into the PRU INTC before start.
 * System event 16 (PRU -> ARM) goes through channel 2 to host interrupt 2
 * (the ARM); system event 17 (ARM -> PRU) through channel 0 to host
 * interrupt 0, which the PRU sees as R31 bit 30. These are the numbers the
 * AM335x kernel's pru_rproc/rpmsg_pru drivers expect for PRU0.
 */
#ifndef TOROCO_RESOURCE_TABLE_H
#define TOROCO_RESOURCE_TABLE_H

#include <stddef.h>
#include <rsc_types.h>
#include "pru_virtio_ids.h"

#define TO_ARM_HOST 16
#define FROM_ARM_HOST 17
#define HOST_UNUSED 255
#define PRU_RPMSG_VQ0_SIZE 16
#define PRU_RPMSG_VQ1_SIZE 16
#define RPMSG_PRU_C0_FEATURES 1      /* VIRTIO_RPMSG_F_NS: name service announcements */

struct my_resource_table {
    struct resource_table base;
    uint32_t offset[2];
    struct fw_rsc_vdev rpmsg_vdev;
    struct fw_rsc_vdev_vring rpmsg_vring0;
    struct fw_rsc_vdev_vring rpmsg_vring1;
    struct fw_rsc_custom pru_ints;
};

/* channel -> host interrupt, system event -> channel */
static struct ch_map pru_intc_map[] = {
    {TO_ARM_HOST, 2},
    {FROM_ARM_HOST, 0},
};

#if defined(__GNUC__)
#define TOROCO_RESOURCE_SECTION __attribute__((section(".resource_table"), used))
#else
#pragma DATA_SECTION(resourceTable, ".resource_table")
#pragma RETAIN(resourceTable)
#define TOROCO_RESOURCE_SECTION
#endif

TOROCO_RESOURCE_SECTION
struct my_resource_table resourceTable = {
    {1, 2, {0, 0}},
    {
        offsetof(struct my_resource_table, rpmsg_vdev),
        offsetof(struct my_resource_table, pru_ints),
    },
    {
        (uint32_t)TYPE_VDEV, (uint32_t)VIRTIO_ID_RPMSG, (uint32_t)0,
        (uint32_t)RPMSG_PRU_C0_FEATURES, (uint32_t)0, (uint32_t)0, (uint8_t)0,
        (uint8_t)2, {(uint8_t)0, (uint8_t)0},
    },
    {0, 16, PRU_RPMSG_VQ0_SIZE, 1, 0},
    {0, 16, PRU_RPMSG_VQ1_SIZE, 2, 0},
    {
        TYPE_CUSTOM, TYPE_PRU_INTS, sizeof(struct fw_rsc_custom_ints),
        {
            0x0000,
            /* channel for each of the 10 host interrupts; 0 and 2 used */
            {0, HOST_UNUSED, 2, HOST_UNUSED, HOST_UNUSED, HOST_UNUSED,
             HOST_UNUSED, HOST_UNUSED, HOST_UNUSED, HOST_UNUSED},
            (sizeof(pru_intc_map) / sizeof(struct ch_map)),
            pru_intc_map,
        },
    },
};

#endif
