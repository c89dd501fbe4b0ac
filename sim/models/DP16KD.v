// Simulation model of the ECP5 DP16KD block RAM as springflat instantiates it: a ROM read on port A
// (hdl/rom.py) and a simple dual-port RAM, written on port A and read on port B (hdl/block_ram.py);
// also what Yosys's synth_ecp5 makes of an inferred ROM or RAM (the tests below). Either port reads
// or writes, DATA_WIDTH 1, 2, 4, 9 or 18 (the two ports may differ); the address sits on AD13..
// downwards, its unused low bits 0, except that in the 18-bit configuration a writing port's AD1
// and AD0 are the byte enables of bits 17..9 and 8..0. CE is the address register's clock enable
// (a write needs CE and WE), REGMODE "NOREG" or "OUTREG" (the output register on OCE),
// WRITEMODE "NORMAL" (a write leaves the port's output), "WRITETHROUGH" (the new word) or
// "READBEFOREWRITE" (the old one). INITVAL_xx hold 16 rows of 18 bits each (20-bit groups); a
// narrow word sits in the low 8 bits of a 9-bit byte, low address first. Both ports on one clock:
// a read of bits the other port writes at the same edge reads X, two writes to the same bits write
// X (the device's collision is undefined). The packing and pins are checked against Yosys's own
// mapping (tests/test_synth.py::test_dp16kd_model_reads_what_yosys_maps and
// ::test_dp16kd_model_is_the_ram_yosys_maps). RST high, chip selects or any other use stop the
// simulation.
`timescale 1ns/1ps
module DP16KD (
    input DIA17, DIA16, DIA15, DIA14, DIA13, DIA12, DIA11, DIA10, DIA9, DIA8, DIA7, DIA6, DIA5, DIA4, DIA3, DIA2, DIA1, DIA0,
    input ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0,
    input CEA, OCEA, CLKA, WEA, RSTA, CSA2, CSA1, CSA0,
    output DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0,
    input DIB17, DIB16, DIB15, DIB14, DIB13, DIB12, DIB11, DIB10, DIB9, DIB8, DIB7, DIB6, DIB5, DIB4, DIB3, DIB2, DIB1, DIB0,
    input ADB13, ADB12, ADB11, ADB10, ADB9, ADB8, ADB7, ADB6, ADB5, ADB4, ADB3, ADB2, ADB1, ADB0,
    input CEB, OCEB, CLKB, WEB, RSTB, CSB2, CSB1, CSB0,
    output DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0
);
    parameter DATA_WIDTH_A = 18;
    parameter DATA_WIDTH_B = 18;
    parameter REGMODE_A = "NOREG";
    parameter REGMODE_B = "NOREG";
    parameter RESETMODE = "SYNC";
    parameter ASYNC_RESET_RELEASE = "SYNC";
    parameter CSDECODE_A = "0b000";
    parameter CSDECODE_B = "0b000";
    parameter WRITEMODE_A = "NORMAL";
    parameter WRITEMODE_B = "NORMAL";
    parameter GSR = "ENABLED";
    parameter INITVAL_00 = 320'h0;
    parameter INITVAL_01 = 320'h0;
    parameter INITVAL_02 = 320'h0;
    parameter INITVAL_03 = 320'h0;
    parameter INITVAL_04 = 320'h0;
    parameter INITVAL_05 = 320'h0;
    parameter INITVAL_06 = 320'h0;
    parameter INITVAL_07 = 320'h0;
    parameter INITVAL_08 = 320'h0;
    parameter INITVAL_09 = 320'h0;
    parameter INITVAL_0A = 320'h0;
    parameter INITVAL_0B = 320'h0;
    parameter INITVAL_0C = 320'h0;
    parameter INITVAL_0D = 320'h0;
    parameter INITVAL_0E = 320'h0;
    parameter INITVAL_0F = 320'h0;
    parameter INITVAL_10 = 320'h0;
    parameter INITVAL_11 = 320'h0;
    parameter INITVAL_12 = 320'h0;
    parameter INITVAL_13 = 320'h0;
    parameter INITVAL_14 = 320'h0;
    parameter INITVAL_15 = 320'h0;
    parameter INITVAL_16 = 320'h0;
    parameter INITVAL_17 = 320'h0;
    parameter INITVAL_18 = 320'h0;
    parameter INITVAL_19 = 320'h0;
    parameter INITVAL_1A = 320'h0;
    parameter INITVAL_1B = 320'h0;
    parameter INITVAL_1C = 320'h0;
    parameter INITVAL_1D = 320'h0;
    parameter INITVAL_1E = 320'h0;
    parameter INITVAL_1F = 320'h0;
    parameter INITVAL_20 = 320'h0;
    parameter INITVAL_21 = 320'h0;
    parameter INITVAL_22 = 320'h0;
    parameter INITVAL_23 = 320'h0;
    parameter INITVAL_24 = 320'h0;
    parameter INITVAL_25 = 320'h0;
    parameter INITVAL_26 = 320'h0;
    parameter INITVAL_27 = 320'h0;
    parameter INITVAL_28 = 320'h0;
    parameter INITVAL_29 = 320'h0;
    parameter INITVAL_2A = 320'h0;
    parameter INITVAL_2B = 320'h0;
    parameter INITVAL_2C = 320'h0;
    parameter INITVAL_2D = 320'h0;
    parameter INITVAL_2E = 320'h0;
    parameter INITVAL_2F = 320'h0;
    parameter INITVAL_30 = 320'h0;
    parameter INITVAL_31 = 320'h0;
    parameter INITVAL_32 = 320'h0;
    parameter INITVAL_33 = 320'h0;
    parameter INITVAL_34 = 320'h0;
    parameter INITVAL_35 = 320'h0;
    parameter INITVAL_36 = 320'h0;
    parameter INITVAL_37 = 320'h0;
    parameter INITVAL_38 = 320'h0;
    parameter INITVAL_39 = 320'h0;
    parameter INITVAL_3A = 320'h0;
    parameter INITVAL_3B = 320'h0;
    parameter INITVAL_3C = 320'h0;
    parameter INITVAL_3D = 320'h0;
    parameter INITVAL_3E = 320'h0;
    parameter INITVAL_3F = 320'h0;

    wire [20479:0] init = {INITVAL_3F, INITVAL_3E, INITVAL_3D, INITVAL_3C, INITVAL_3B, INITVAL_3A, INITVAL_39, INITVAL_38, INITVAL_37, INITVAL_36, INITVAL_35, INITVAL_34, INITVAL_33, INITVAL_32, INITVAL_31, INITVAL_30, INITVAL_2F, INITVAL_2E, INITVAL_2D, INITVAL_2C, INITVAL_2B, INITVAL_2A, INITVAL_29, INITVAL_28, INITVAL_27, INITVAL_26, INITVAL_25, INITVAL_24, INITVAL_23, INITVAL_22, INITVAL_21, INITVAL_20, INITVAL_1F, INITVAL_1E, INITVAL_1D, INITVAL_1C, INITVAL_1B, INITVAL_1A, INITVAL_19, INITVAL_18, INITVAL_17, INITVAL_16, INITVAL_15, INITVAL_14, INITVAL_13, INITVAL_12, INITVAL_11, INITVAL_10, INITVAL_0F, INITVAL_0E, INITVAL_0D, INITVAL_0C, INITVAL_0B, INITVAL_0A, INITVAL_09, INITVAL_08, INITVAL_07, INITVAL_06, INITVAL_05, INITVAL_04, INITVAL_03, INITVAL_02, INITVAL_01, INITVAL_00};
    reg [17:0] rows [0:1023];

    wire [13:0] ada = {ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0};
    wire [13:0] adb = {ADB13, ADB12, ADB11, ADB10, ADB9, ADB8, ADB7, ADB6, ADB5, ADB4, ADB3, ADB2, ADB1, ADB0};
    wire [17:0] dia = {DIA17, DIA16, DIA15, DIA14, DIA13, DIA12, DIA11, DIA10, DIA9, DIA8, DIA7, DIA6, DIA5, DIA4, DIA3, DIA2, DIA1, DIA0};
    wire [17:0] dib = {DIB17, DIB16, DIB15, DIB14, DIB13, DIB12, DIB11, DIB10, DIB9, DIB8, DIB7, DIB6, DIB5, DIB4, DIB3, DIB2, DIB1, DIB0};

    // where a port's word sits: its row and the mask of its bits in that row
    function integer abits(input integer w);
        abits = w == 1 ? 14 : w == 2 ? 13 : w == 4 ? 12 : w == 9 ? 11 : 10;
    endfunction
    function integer row_of(input integer w, input [13:0] ad);
        integer a, per_row;
        begin
            a = ad >> (14 - abits(w));
            per_row = w == 18 ? 1 : 2 * (w >= 9 ? 1 : 8 / w);
            row_of = a / per_row;
        end
    endfunction
    function integer pos_of(input integer w, input [13:0] ad);
        integer a, per_byte, k;
        begin
            a = ad >> (14 - abits(w));
            per_byte = w >= 9 ? 1 : 8 / w;
            k = a % (w == 18 ? 1 : 2 * per_byte);
            pos_of = w == 18 ? 0 : (k / per_byte) * 9 + (k % per_byte) * w;
        end
    endfunction
    // the bits a write changes: the word's, or in the 18-bit configuration the enabled bytes
    function [17:0] write_mask(input integer w, input [13:0] ad);
        begin
            if (w == 18) write_mask = {{9{ad[1]}}, {9{ad[0]}}};
            else write_mask = ((18'd1 << w) - 1) << pos_of(w, ad);
        end
    endfunction

    integer i;
    reg [17:0] qa, qb, outa, outb;  // the data latches and the output registers
    initial begin
        if (!(DATA_WIDTH_A == 1 || DATA_WIDTH_A == 2 || DATA_WIDTH_A == 4 || DATA_WIDTH_A == 9 || DATA_WIDTH_A == 18) ||
            !(DATA_WIDTH_B == 1 || DATA_WIDTH_B == 2 || DATA_WIDTH_B == 4 || DATA_WIDTH_B == 9 || DATA_WIDTH_B == 18)) begin
            $display("DP16KD model: DATA_WIDTH %0d/%0d is not a DP16KD width", DATA_WIDTH_A, DATA_WIDTH_B); $finish;
        end
        if ((REGMODE_A != "NOREG" && REGMODE_A != "OUTREG") || (REGMODE_B != "NOREG" && REGMODE_B != "OUTREG")) begin
            $display("DP16KD model: REGMODE %s/%s not modelled", REGMODE_A, REGMODE_B); $finish;
        end
        if (CSDECODE_A != "0b000" || CSDECODE_B != "0b000") begin
            $display("DP16KD model: CSDECODE %s/%s not modelled", CSDECODE_A, CSDECODE_B); $finish;
        end
        for (i = 0; i < 1024; i = i + 1) rows[i] = init[i * 20 +: 18];
        qa = 0; qb = 0; outa = 0; outb = 0;
    end

    wire a_on = CEA === 1'b1, b_on = CEB === 1'b1;
    wire a_writes = a_on && WEA === 1'b1, b_writes = b_on && WEB === 1'b1;
    // a collision: the two ports at the same edge on overlapping bits of one row, one of them writing
    wire same_row = row_of(DATA_WIDTH_A, ada) == row_of(DATA_WIDTH_B, adb);
    wire a_hits_b = same_row && (write_mask(DATA_WIDTH_A, ada) & (((18'd1 << DATA_WIDTH_B) - 1) << pos_of(DATA_WIDTH_B, adb))) != 0;
    wire b_hits_a = same_row && (write_mask(DATA_WIDTH_B, adb) & (((18'd1 << DATA_WIDTH_A) - 1) << pos_of(DATA_WIDTH_A, ada))) != 0;
    always @(posedge CLKA) begin
        if (RSTA === 1'b1 || CSA2 === 1'b1 || CSA1 === 1'b1 || CSA0 === 1'b1) begin
            $display("DP16KD model: RSTA and the chip selects of port A are not modelled"); $finish;
        end
        if (a_writes) begin
            rows[row_of(DATA_WIDTH_A, ada)] <= (b_writes && b_hits_a) ? 18'bx :
                (rows[row_of(DATA_WIDTH_A, ada)] & ~write_mask(DATA_WIDTH_A, ada))
                | ((dia << pos_of(DATA_WIDTH_A, ada)) & write_mask(DATA_WIDTH_A, ada));
            if (WRITEMODE_A == "WRITETHROUGH") qa <= dia & ((18'd1 << DATA_WIDTH_A) - 1);
            else if (WRITEMODE_A == "READBEFOREWRITE")
                qa <= (rows[row_of(DATA_WIDTH_A, ada)] >> pos_of(DATA_WIDTH_A, ada)) & ((18'd1 << DATA_WIDTH_A) - 1);
        end else if (a_on) begin
            qa <= (b_writes && b_hits_a) ? 18'bx :
                (rows[row_of(DATA_WIDTH_A, ada)] >> pos_of(DATA_WIDTH_A, ada)) & ((18'd1 << DATA_WIDTH_A) - 1);
        end
        if (OCEA === 1'b1) outa <= qa;
    end
    always @(posedge CLKB) begin
        if (RSTB === 1'b1 || CSB2 === 1'b1 || CSB1 === 1'b1 || CSB0 === 1'b1) begin
            $display("DP16KD model: RSTB and the chip selects of port B are not modelled"); $finish;
        end
        if (b_writes) begin
            if (!(a_writes && a_hits_b))
                rows[row_of(DATA_WIDTH_B, adb)] <= (rows[row_of(DATA_WIDTH_B, adb)] & ~write_mask(DATA_WIDTH_B, adb))
                    | ((dib << pos_of(DATA_WIDTH_B, adb)) & write_mask(DATA_WIDTH_B, adb));
            if (WRITEMODE_B == "WRITETHROUGH") qb <= dib & ((18'd1 << DATA_WIDTH_B) - 1);
            else if (WRITEMODE_B == "READBEFOREWRITE")
                qb <= (rows[row_of(DATA_WIDTH_B, adb)] >> pos_of(DATA_WIDTH_B, adb)) & ((18'd1 << DATA_WIDTH_B) - 1);
        end else if (b_on) begin
            qb <= (a_writes && a_hits_b) ? 18'bx :
                (rows[row_of(DATA_WIDTH_B, adb)] >> pos_of(DATA_WIDTH_B, adb)) & ((18'd1 << DATA_WIDTH_B) - 1);
        end
        if (OCEB === 1'b1) outb <= qb;
    end
    wire [17:0] doa = REGMODE_A == "OUTREG" ? outa : qa;
    wire [17:0] dob = REGMODE_B == "OUTREG" ? outb : qb;
    assign {DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0} = doa;
    assign {DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0} = dob;
endmodule
