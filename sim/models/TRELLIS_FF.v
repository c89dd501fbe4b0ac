// Simulation model of the ECP5 TRELLIS_FF flip-flop as springflat instantiates it (hdl/dsp.py's
// kept_register: the block RAMs' pin registers, register copies): CEMUX "1" (always enabled), LSR low,
// REGSET "RESET"; Q starts at 0. Any other use stops the simulation.
`timescale 1ns/1ps
module TRELLIS_FF (input CLK, LSR, CE, DI, M, output reg Q);
    parameter GSR = "ENABLED";
    parameter [127:0] CEMUX = "1";
    parameter CLKMUX = "CLK";
    parameter LSRMUX = "LSR";
    parameter SRMODE = "LSR_OVER_CE";
    parameter REGSET = "RESET";
    parameter [127:0] LSRMODE = "LSR";
    initial begin
        if (CEMUX != "1" || CLKMUX != "CLK" || REGSET != "RESET") begin
            $display("TRELLIS_FF model: unsupported parameters");
            $finish;
        end
        Q = 1'b0;
    end
    always @(posedge CLK) begin
        if (LSR === 1'b1) begin
            $display("TRELLIS_FF model: LSR is not supported");
            $finish;
        end
        Q <= DI;
    end
endmodule
